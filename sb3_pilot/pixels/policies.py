"""
The pixel-only SAC policy (:class:`PixelGoalSACPolicy`): one image encoder (:mod:`sb3_pilot.pixels.encoder`) shared
by the actor and the critic and trained by the critic's loss only, the paper's way, and its auxiliary loss that
predicts the achieved goal from the image.

It takes part in the lean gradient step of :class:`~sb3_pilot.sac.LeanSAC` through that step's extension point
(:class:`~sb3_pilot.common.lean.StepHooks`): :meth:`PixelGoalSACPolicy.encode` encodes a batch once per gradient step,
:meth:`PixelGoalSACPolicy.critic_auxiliary_losses` adds the goal prediction to the critic's loss.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import ContinuousCritic
from stable_baselines3.common.preprocessing import get_flattened_obs_dim
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.type_aliases import PyTorchObs
from stable_baselines3.sac.policies import Actor, SACPolicy
from torch import nn

from sb3_pilot.checks import check_number
from sb3_pilot.optimizers import lean_optimizer_kwargs
from sb3_pilot.pixels.encoder import ACHIEVED_KEY, GOAL_KEY, PixelGoalExtractor, RandomShift


@dataclass(frozen=True)
class EncodedObservations:
    """
    A batch of observations already through the shared encoder: ``phi(s)`` with its graph, as
    :meth:`PixelGoalSACPolicy.encode` returns it. The actor and the critic of :class:`PixelGoalSACPolicy` read it in
    place of the observations (the actor, and the critic at the actor's actions, without its gradient).

    :param observations: the batch ``s`` itself (its ``achieved_goal`` is the goal prediction's target)
    :param features: the features extractor's output (image features and desired goal), ``(batch, features_dim)``
    """

    observations: PyTorchObs
    features: th.Tensor


class _DetachedFeaturesActor(Actor):
    """SAC actor whose (shared) features extractor gets no gradient: its features are computed without one."""

    def extract_features(  # type: ignore[override]
        self, obs: PyTorchObs | EncodedObservations, features_extractor: BaseFeaturesExtractor
    ) -> th.Tensor:
        if isinstance(obs, EncodedObservations):
            return obs.features.detach()
        with th.no_grad():
            return super().extract_features(obs, features_extractor)


class _EncoderTrainingCritic(ContinuousCritic):
    """
    Critic that trains the features extractor it shares with the actor, from the critic's loss only.

    SB3's ``SAC.train`` calls the critic twice: on the replay actions for the critic's loss, then on the actor's
    actions (which require a gradient) for the actor's loss. Features get a gradient in the first call only, so
    the actor's loss, which the actor's optimizer minimises, never reaches the encoder (and its backward pass skips
    it, as DrQ's ``detach`` does).

    Given :class:`EncodedObservations` (features computed once, :meth:`PixelGoalSACPolicy.encode`), it reads them
    with their gradient in the same cases, detached otherwise.

    With a ``goal_head`` (:class:`PixelGoalSACPolicy`'s ``goal_prediction``), the image features of that first call
    are kept as ``image_features`` for the auxiliary loss of the same gradient step.
    """

    def __init__(self, *args: Any, **kwargs: Any):
        super().__init__(*args, **kwargs)
        self.goal_head: nn.Linear | None = None
        self.image_features: th.Tensor | None = None

    def forward(self, obs: PyTorchObs | EncodedObservations, actions: th.Tensor) -> tuple[th.Tensor, ...]:
        trains_encoder = th.is_grad_enabled() and not actions.requires_grad
        if isinstance(obs, EncodedObservations):
            features = obs.features if trains_encoder else obs.features.detach()
        else:
            with th.set_grad_enabled(trains_encoder):
                features = self.extract_features(obs, self.features_extractor)
        if self.goal_head is not None and features.requires_grad:
            self.image_features = features[:, : self.goal_head.in_features]
        qvalue_input = th.cat([features, actions], dim=1)
        return tuple(q_net(qvalue_input) for q_net in self.q_networks)


class PixelGoalSACPolicy(SACPolicy):
    """
    SAC policy for the image tasks, the paper's way: one :class:`PixelGoalExtractor` (by default) shared by the actor
    and the critic, trained by the critic's loss only (it is in the critic's optimizer, not the actor's; the actor
    reads its features without gradient). The target critic has its own copy, updated by Polyak averaging with
    the critic's other weights and read without gradient, as in SB3.

    The extractor's :class:`RandomShift` (``random_shift``) follows the policy's training mode, the target critic's
    copy included (its networks stay in evaluation mode): in ``train()`` the target values are computed from shifted
    next observations, as in DrQ.

    With ``goal_prediction > 0``, the encoder also learns to predict the achieved goal ``g`` from the image: a linear
    head ``g_hat`` on the image features ``phi(o)`` of the critic's pass, and the critic's loss gets
    ``goal_prediction * mean ||g_hat(phi(o)) - g||^2`` (:meth:`goal_prediction_loss`; ``g`` as the agent's buffer holds
    it, standardised where the goal entries are normalised). The goal is a training target only: the actor and the
    critic still read the image and the desired goal alone. The pixel agent must locate its arm more finely than
    the success radius (Reacher-Image: 0.02, under 3 pixels), which the critic's sparse-reward loss alone teaches
    slowly. The loss is added by :class:`~sb3_pilot.sac.LeanSAC` (the zoo's ``lean_sac``), which calls
    :meth:`critic_auxiliary_losses`; SB3's ``SAC`` would ignore it, so training with it refuses to start.

    In an RL-Zoo YAML: ``policy: sb3_pilot.pixels.PixelGoalSACPolicy``. Same parameters as SB3's
    ``MultiInputPolicy`` for SAC, but ``features_extractor_class`` defaults to :class:`PixelGoalExtractor` and
    ``share_features_extractor`` must stay True (the sharing described above).

    With ``online_target_features=True`` (DrQ-v2's target, Yarats et al. 2021), the target critic's Q-networks read
    the shared encoder's features of the next observations, the pass the actor's next action reads, instead of its own
    Polyak-averaged copy's: the encoder runs twice a gradient step instead of three times (about 1/6 less CPU time
    per gradient step on ``Pilot/FetchReachImage-v0``), and the TD targets change (the copy is kept, unread). Like the
    goal prediction, it needs :class:`~sb3_pilot.sac.LeanSAC`, which calls :meth:`encode_next`.

    :param goal_prediction: weight of the auxiliary goal-prediction loss in the critic's loss (0: none)
    :param online_target_features: whether the target critic reads the shared encoder's features of the next
        observations (DrQ-v2) instead of its own encoder copy's
    """

    #: set by the algorithm that calls :meth:`encode` and :meth:`critic_auxiliary_losses` (:class:`~sb3_pilot.sac.LeanSAC`)
    step_hooks_attached: bool = False

    def __init__(
        self,
        *args: Any,
        features_extractor_class: type[BaseFeaturesExtractor] = PixelGoalExtractor,
        share_features_extractor: bool = True,
        goal_prediction: float = 0.0,
        online_target_features: bool = False,
        **kwargs: Any,
    ):
        if not share_features_extractor:
            raise ValueError("PixelGoalSACPolicy shares its encoder between actor and critic: use MultiInputPolicy not to.")
        check_number("goal_prediction", goal_prediction, minimum=0.0)
        if goal_prediction and not issubclass(features_extractor_class, PixelGoalExtractor):
            raise ValueError(
                f"goal_prediction reads PixelGoalExtractor's image features; features_extractor_class is "
                f"{features_extractor_class.__name__}."
            )
        space = kwargs.get("observation_space", args[0] if args else None)
        if goal_prediction and (not isinstance(space, spaces.Dict) or ACHIEVED_KEY not in space.spaces):
            raise ValueError(f"goal_prediction predicts the observation's {ACHIEVED_KEY!r}, which it has not: {space}.")
        self.goal_prediction = float(goal_prediction)
        self.online_target_features = bool(online_target_features)
        # fused Adam, as the lean policies (same updates, one kernel per optimizer step instead of one per parameter)
        optimizer_class = kwargs.get("optimizer_class", th.optim.Adam)
        kwargs["optimizer_kwargs"] = lean_optimizer_kwargs(optimizer_class, kwargs.get("optimizer_kwargs"))
        super().__init__(*args, features_extractor_class=features_extractor_class, share_features_extractor=True, **kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(goal_prediction=self.goal_prediction, online_target_features=self.online_target_features)
        return data

    def _build(self, lr_schedule: Any) -> None:
        self.actor = self.make_actor()
        self.critic = self.make_critic(features_extractor=self.actor.features_extractor)
        # the actor's optimizer leaves the shared encoder alone; the critic's trains it
        actor_parameters = [param for name, param in self.actor.named_parameters() if "features_extractor" not in name]
        self.actor.optimizer = self.optimizer_class(actor_parameters, lr=lr_schedule(1), **self.optimizer_kwargs)  # type: ignore[call-arg]
        self.critic.optimizer = self.optimizer_class(  # type: ignore[call-arg]
            self.critic.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs
        )
        self.critic_target = self.make_critic(features_extractor=None)
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.critic_target.set_training_mode(False)
        self._target_augmentations = [module for module in self.critic_target.modules() if isinstance(module, RandomShift)]

    def set_training_mode(self, mode: bool) -> None:
        """SB3's switch of the actor's and the critic's mode, and of the target critic's augmentation (see above)."""
        if mode and self.goal_prediction and not self.step_hooks_attached:
            raise ValueError(
                f"PixelGoalSACPolicy(goal_prediction={self.goal_prediction}) needs an algorithm that adds its loss: "
                "sb3_pilot.sac.LeanSAC (the zoo's lean_sac); SB3's SAC would train without it."
            )
        if mode and self.online_target_features and not self.step_hooks_attached:
            raise ValueError(
                "PixelGoalSACPolicy(online_target_features=True) needs an algorithm that calls encode_next: "
                "sb3_pilot.sac.LeanSAC (the zoo's lean_sac); SB3's SAC would use the target's encoder copy."
            )
        super().set_training_mode(mode)
        for augmentation in self._target_augmentations:
            augmentation.train(mode)

    def make_actor(self, features_extractor: BaseFeaturesExtractor | None = None) -> Actor:
        actor_kwargs = self._update_features_extractor(self.actor_kwargs, features_extractor)
        return _DetachedFeaturesActor(**actor_kwargs).to(self.device)

    def make_critic(self, features_extractor: BaseFeaturesExtractor | None = None) -> ContinuousCritic:
        critic_kwargs = self._update_features_extractor(self.critic_kwargs, features_extractor)
        critic = _EncoderTrainingCritic(**critic_kwargs)
        if self.goal_prediction:
            observation_space = self.observation_space
            assert isinstance(observation_space, spaces.Dict)
            image_features = critic.features_extractor.features_dim - get_flattened_obs_dim(observation_space[GOAL_KEY])
            critic.goal_head = nn.Linear(image_features, get_flattened_obs_dim(observation_space[ACHIEVED_KEY]))
        return critic.to(self.device)

    def encode(self, observations: PyTorchObs) -> EncodedObservations:
        """
        ``phi(s)``, once for a gradient step (DrQ-v2's order): the critic's encoder on the observations (shifted in
        training, with the gradient the critic's loss trains it by), which the actor, the critic and the actor's loss
        then read instead of encoding the batch three times. :class:`~sb3_pilot.sac.LeanSAC` calls it; the next
        observations are encoded as before (by the encoder for the actor, by the target's copy for the target).

        :param observations: the batch's observations ``s``
        :return: their features, for the actor's and the critic's calls of this gradient step
        """
        return EncodedObservations(observations, self.critic.extract_features(observations, self.critic.features_extractor))

    def encode_next(self, next_observations: PyTorchObs) -> PyTorchObs | EncodedObservations:
        """
        What the actor's next action and the target critic read for ``s'`` in a gradient step (the lean step's hook,
        called without gradient): ``s'`` itself (each encodes it, the target with its own copy), or with
        ``online_target_features`` the shared encoder's features of ``s'`` (shifted in training), computed once for both.

        :param next_observations: the batch's next observations ``s'``
        :return: ``next_observations``, or their features (detached)
        """
        if not self.online_target_features:
            return next_observations
        with th.no_grad():
            features = self.actor.extract_features(next_observations, self.actor.features_extractor)
        return EncodedObservations(next_observations, features)

    def critic_auxiliary_losses(self, observations: PyTorchObs | EncodedObservations) -> dict[str, tuple[float, th.Tensor]]:
        """
        The losses this policy adds to the critic's (the lean step's hook, after the critic's pass on ``observations``):
        the goal prediction (:meth:`goal_prediction_loss`) weighted by ``goal_prediction``, where it has one.

        :param observations: the batch the critic was just called on, or its encoding (:meth:`encode`)
        :return: ``{"goal_prediction_loss": (goal_prediction, loss)}``, or no loss
        """
        if not self.goal_prediction:
            return {}
        return {"goal_prediction_loss": (self.goal_prediction, self.goal_prediction_loss(observations))}

    def goal_prediction_loss(self, observations: PyTorchObs | EncodedObservations) -> th.Tensor:
        """
        The auxiliary loss ``mean_batch ||g_hat(phi(o)) - g||^2`` of the critic's last encoder-training pass, which
        must have been on these observations (the critic's loss of the same gradient step).

        :param observations: the batch the critic was just called on (its ``achieved_goal`` is ``g``), or its encoding
        :return: the loss (a scalar with gradients for the encoder and the head)
        """
        if isinstance(observations, EncodedObservations):
            observations = observations.observations
        features = self.critic.image_features
        assert isinstance(observations, dict) and self.critic.goal_head is not None
        goals = observations[ACHIEVED_KEY].flatten(start_dim=1)
        if features is None or features.shape[0] != goals.shape[0]:
            raise RuntimeError("goal_prediction_loss needs the critic's encoder-training pass on this batch first.")
        return ((self.critic.goal_head(features) - goals) ** 2).sum(dim=1).mean()
