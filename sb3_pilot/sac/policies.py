"""SB3's SAC policies with the lean update's networks: the twin critics as one ensemble and fused Adam."""

from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, CombinedExtractor, NatureCNN
from stable_baselines3.common.type_aliases import Schedule
from stable_baselines3.sac.policies import SACPolicy

from sb3_pilot.common.critics import EnsembleCritic
from sb3_pilot.common.lean import set_training_flags
from sb3_pilot.optimizers import lean_optimizer_kwargs


class LeanSACPolicy(SACPolicy):
    """
    SB3's ``SACPolicy`` (same actor, same arguments) whose critic and target critic are an
    :class:`~sb3_pilot.common.critics.EnsembleCritic`, and whose Adam optimizers are fused unless ``optimizer_kwargs``
    says otherwise.

    :param observation_space: Observation space
    :param action_space: Action space
    :param lr_schedule: Learning rate schedule
    :param optimizer_class: The optimizer to use (``th.optim.Adam`` by default)
    :param optimizer_kwargs: Its keyword arguments (Adam: ``fused=True`` unless ``fused`` or ``foreach`` is given)
    :param kwargs: the other keyword arguments of ``SACPolicy`` (``net_arch``, ``n_critics``, ...)
    """

    critic: EnsembleCritic
    critic_target: EnsembleCritic

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        **kwargs: Any,
    ):
        super().__init__(
            observation_space,
            action_space,
            lr_schedule,
            optimizer_class=optimizer_class,
            optimizer_kwargs=lean_optimizer_kwargs(optimizer_class, optimizer_kwargs),
            **kwargs,
        )

    def _build(self, lr_schedule: Schedule) -> None:
        super()._build(lr_schedule)
        self._mode_switched_modules = [self, *self.actor.modules(), *self.critic.modules()]

    def set_training_mode(self, mode: bool) -> None:
        """SB3's switch of the actor's and the critic's mode (the target critic stays in evaluation mode), cheaply."""
        if mode != self.training:
            set_training_flags(self._mode_switched_modules, mode)

    def make_critic(self, features_extractor: BaseFeaturesExtractor | None = None) -> EnsembleCritic:
        critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)
        return EnsembleCritic(**critic_kwargs).to(self.device)


MlpPolicy = LeanSACPolicy


class CnnPolicy(LeanSACPolicy):
    """:class:`LeanSACPolicy` with SB3's ``NatureCNN`` features extractor (image observations)."""

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        features_extractor_class: type[BaseFeaturesExtractor] = NatureCNN,
        **kwargs: Any,
    ):
        super().__init__(
            observation_space, action_space, lr_schedule, features_extractor_class=features_extractor_class, **kwargs
        )


class MultiInputPolicy(LeanSACPolicy):
    """:class:`LeanSACPolicy` with SB3's ``CombinedExtractor`` (Dict observations: goal envs)."""

    def __init__(
        self,
        observation_space: spaces.Dict,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        features_extractor_class: type[BaseFeaturesExtractor] = CombinedExtractor,
        **kwargs: Any,
    ):
        super().__init__(
            observation_space, action_space, lr_schedule, features_extractor_class=features_extractor_class, **kwargs
        )
