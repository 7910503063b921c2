"""Networks of UDPO: goal-conditioned state planner, inverse dynamics and twin Q critics."""

import math
from typing import Any, NamedTuple

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BaseModel, BasePolicy, ContinuousCritic
from stable_baselines3.common.preprocessing import get_action_dim, is_image_space
from stable_baselines3.common.torch_layers import (
    BaseFeaturesExtractor,
    CombinedExtractor,
    FlattenExtractor,
    create_mlp,
    get_actor_critic_arch,
)
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from torch import nn
from torch.nn import functional as F

# Same bounds as SB3's SAC actor
LOG_STD_MAX = 2
LOG_STD_MIN = -20
_HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)

#: Keys of a Dict observation that form the planner state, in this order.
PLANNER_STATE_KEYS = ("observation", "achieved_goal")
#: Keys a Dict observation may hold.
SUPPORTED_KEYS = frozenset((*PLANNER_STATE_KEYS, "desired_goal"))


def gaussian_log_prob(value: th.Tensor, mean: th.Tensor, log_std: th.Tensor) -> th.Tensor:
    """Log-density of a diagonal Gaussian, summed over the last dimension."""
    return (-0.5 * ((value - mean) * th.exp(-log_std)) ** 2 - log_std - _HALF_LOG_2PI).sum(dim=-1)


def squashed_gaussian_sample(mean: th.Tensor, log_std: th.Tensor, deterministic: bool = False) -> tuple[th.Tensor, th.Tensor]:
    """
    Reparameterised sample of ``tanh(u)``, ``u ~ N(mean, exp(log_std))``, and its log-probability.

    :param mean: mean of the pre-squash Gaussian
    :param log_std: log standard deviation of the pre-squash Gaussian
    :param deterministic: return ``tanh(mean)`` instead of a sample
    :return: the squashed sample and its log-probability (shape ``(batch,)``)
    """
    gaussian = mean if deterministic else mean + th.randn_like(mean) * th.exp(log_std)
    return th.tanh(gaussian), squashed_gaussian_log_prob(gaussian, mean, log_std)


def squashed_gaussian_log_prob(gaussian: th.Tensor, mean: th.Tensor, log_std: th.Tensor) -> th.Tensor:
    """Log-probability of ``tanh(gaussian)`` for ``gaussian ~ N(mean, exp(log_std))``, summed over the last dimension."""
    tanh_log_det = 2 * (math.log(2) - gaussian - F.softplus(-2 * gaussian))  # log(1 - tanh(u)^2), stable
    return gaussian_log_prob(gaussian, mean, log_std) - tanh_log_det.sum(dim=-1)


def check_observation_space(observation_space: spaces.Space) -> None:
    """
    Raise a ``ValueError`` naming the problem if UDPO cannot plan in ``observation_space``.

    UDPO's planner predicts the next *vector* state, so it needs a flat ``Box`` or a ``Dict`` whose entries are flat
    ``Box`` vectors among ``observation``, ``achieved_goal`` and ``desired_goal`` (with ``observation`` present).
    """
    if isinstance(observation_space, spaces.Dict):
        unknown = set(observation_space.spaces) - SUPPORTED_KEYS
        if unknown:
            raise ValueError(
                f"UDPO supports Dict observations with keys {sorted(SUPPORTED_KEYS)} only, got unsupported keys "
                f"{sorted(unknown)}."
            )
        if "observation" not in observation_space.spaces:
            raise ValueError("UDPO needs an 'observation' entry in a Dict observation space: the planner plans its next value")
        for key, subspace in observation_space.spaces.items():
            _check_vector_space(subspace, f"observation entry '{key}'")
    else:
        _check_vector_space(observation_space, "observation space")


def _check_vector_space(space: spaces.Space, what: str) -> None:
    if not isinstance(space, spaces.Box) or is_image_space(space, check_channels=False) or len(space.shape) != 1:
        raise ValueError(
            f"UDPO's state planner predicts flat vector states, but the {what} is {space}. Images are not supported: "
            "for image targets, train SAC + HER with sb3_pilot.PilotBonusWrapper and a planner distilled from a vector source."
        )


def planner_state_dim(observation_space: spaces.Space) -> int:
    """Size of the planner state: ``observation`` (+ ``achieved_goal``) for a Dict, the whole vector for a Box."""
    if isinstance(observation_space, spaces.Dict):
        return sum(int(observation_space[key].shape[0]) for key in PLANNER_STATE_KEYS if key in observation_space.spaces)
    return int(observation_space.shape[0])


class Plan(NamedTuple):
    """One pass of the decoupled policy: the planner's distribution, the planned state and the action towards it."""

    state: th.Tensor
    delta_mean: th.Tensor
    delta_log_std: th.Tensor
    planned_state: th.Tensor
    actions: th.Tensor
    log_prob: th.Tensor


class StatePlanner(BaseModel):
    """
    Goal-conditioned state planner ``h(s' | s, g)`` (paper section 3.1).

    A diagonal Gaussian over the *change* of the planner state, reparameterised so that gradients reach ``h``
    through the sampled plan: ``s' = s + mu(s, g) + sigma(s, g) * eps``.
    The planner state ``s`` is ``observation`` concatenated with ``achieved_goal`` (Dict observations) or the
    observation itself (Box observations, DePO's goal-free setting); the network sees the whole observation,
    goals included.

    :param observation_space: Observation space
    :param action_space: Action space (unused by the planner, kept for SB3's model interface)
    :param net_arch: Hidden layer sizes
    :param features_extractor: Network that flattens (and concatenates) the observation
    :param features_dim: Number of features produced by ``features_extractor``
    :param activation_fn: Activation function
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: BaseFeaturesExtractor,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.ReLU,
    ):
        super().__init__(observation_space, action_space, features_extractor=features_extractor, normalize_images=False)
        self.net_arch = net_arch
        self.features_dim = features_dim
        self.activation_fn = activation_fn
        self.state_dim = planner_state_dim(observation_space)
        # One output layer for mean and log-std: fewer kernel launches on the hot path
        self.net = nn.Sequential(*create_mlp(features_dim, 2 * self.state_dim, net_arch, activation_fn))

    def planner_state(self, obs: PyTorchObs) -> th.Tensor:
        """Planner state ``s`` of a (preprocessed) observation batch."""
        if isinstance(obs, dict):
            return th.cat([obs[key] for key in PLANNER_STATE_KEYS if key in obs], dim=1)
        return obs

    def distribution_params(self, obs: PyTorchObs) -> tuple[th.Tensor, th.Tensor, th.Tensor]:
        """
        :param obs: preprocessed observation batch
        :return: planner state ``s``, mean and log-std of the Gaussian over ``s' - s``
        """
        delta_mean, log_std = self.net(self.extract_features(obs, self.features_extractor)).chunk(2, dim=-1)
        return self.planner_state(obs), delta_mean, th.clamp(log_std, LOG_STD_MIN, LOG_STD_MAX)

    def plan(self, obs: PyTorchObs, deterministic: bool = False) -> tuple[th.Tensor, th.Tensor, th.Tensor, th.Tensor]:
        """
        :param obs: preprocessed observation batch
        :param deterministic: return the mean plan instead of a reparameterised sample
        :return: planner state ``s``, mean and log-std of ``s' - s``, and the planned next state ``s'``
        """
        state, delta_mean, log_std = self.distribution_params(obs)
        planned = state + delta_mean
        if not deterministic:
            planned = planned + th.randn_like(delta_mean) * th.exp(log_std)
        return state, delta_mean, log_std, planned

    def forward(self, obs: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        """Planned next state ``s'`` (mean if ``deterministic``, else a reparameterised sample)."""
        return self.plan(obs, deterministic)[3]

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            net_arch=self.net_arch,
            features_dim=self.features_dim,
            activation_fn=self.activation_fn,
            features_extractor=self.features_extractor,
        )
        return data


class InverseDynamics(nn.Module):
    """
    Inverse dynamics ``I(a | s, s')`` (paper eq. "inverse-dynamics"): a tanh-squashed diagonal Gaussian over the
    (normalised) action that takes the planner state from ``s`` to ``s'``. Its input is ``[s, s' - s]``.

    :param state_dim: Size of the planner state
    :param action_dim: Size of the action
    :param net_arch: Hidden layer sizes
    :param activation_fn: Activation function
    """

    optimizer: th.optim.Optimizer

    def __init__(self, state_dim: int, action_dim: int, net_arch: list[int], activation_fn: type[nn.Module] = nn.ReLU):
        super().__init__()
        self.state_dim = state_dim
        self.action_dim = action_dim
        self.net = nn.Sequential(*create_mlp(2 * state_dim, 2 * action_dim, net_arch, activation_fn))

    def distribution_params(self, state: th.Tensor, next_state: th.Tensor) -> tuple[th.Tensor, th.Tensor]:
        """Mean and log-std of the pre-squash Gaussian over actions."""
        mean, log_std = self.net(th.cat([state, next_state - state], dim=1)).chunk(2, dim=-1)
        return mean, th.clamp(log_std, LOG_STD_MIN, LOG_STD_MAX)

    def forward(self, state: th.Tensor, next_state: th.Tensor, deterministic: bool = False) -> tuple[th.Tensor, th.Tensor]:
        """Squashed action in ``[-1, 1]`` and its log-probability."""
        return squashed_gaussian_sample(*self.distribution_params(state, next_state), deterministic=deterministic)

    def log_prob(self, state: th.Tensor, next_state: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """Log-likelihood of buffer actions in ``[-1, 1]`` (the supervised loss is its negative)."""
        mean, log_std = self.distribution_params(state, next_state)
        eps = th.finfo(actions.dtype).eps
        return squashed_gaussian_log_prob(th.atanh(actions.clamp(-1.0 + eps, 1.0 - eps)), mean, log_std)


class UDPOPolicy(BasePolicy):
    """
    Decoupled goal-conditioned policy ``pi(a | s, g) = E_{s' ~ h(.|s, g)} [I(a | s, s')]`` with twin Q critics.

    Acting samples a plan ``s' ~ h(. | s, g)`` and then an action ``a ~ I(. | s, s')``. The log-probability used for
    the entropy terms is ``log I(a | s, s')`` at the sampled plan (as in DePO), not the intractable marginal.

    :param observation_space: Observation space (flat Box, or Dict of flat Box vectors)
    :param action_space: Action space (Box)
    :param lr_schedule: Learning rate schedule of the critic (and of the planner if ``planner_lr_schedule`` is None)
    :param net_arch: Hidden layers: a list shared by all networks, or a dict with keys ``pi`` (planner),
        ``qf`` (critics) and optionally ``inverse_dynamics`` (defaults to ``pi``)
    :param activation_fn: Activation function
    :param features_extractor_class: Features extractor of the planner and critics
    :param features_extractor_kwargs: Keyword arguments for the features extractor
    :param optimizer_class: Optimizer class
    :param optimizer_kwargs: Optimizer keyword arguments (except the learning rate)
    :param n_critics: Number of critic networks
    :param planner_lr_schedule: Learning rate schedule of the state planner (None: ``lr_schedule``)
    :param inverse_dynamics_lr_schedule: Learning rate schedule of the inverse dynamics (None: ``lr_schedule``)
    """

    state_planner: StatePlanner
    inverse_dynamics: InverseDynamics
    critic: ContinuousCritic
    critic_target: ContinuousCritic

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        n_critics: int = 2,
        planner_lr_schedule: Schedule | None = None,
        inverse_dynamics_lr_schedule: Schedule | None = None,
    ):
        check_observation_space(observation_space)
        super().__init__(
            observation_space,
            action_space,
            features_extractor_class,
            features_extractor_kwargs,
            optimizer_class=optimizer_class,
            optimizer_kwargs=optimizer_kwargs,
            squash_output=True,
            normalize_images=False,
        )
        if net_arch is None:
            net_arch = [256, 256]
        planner_arch, critic_arch = get_actor_critic_arch(net_arch)
        self.inverse_dynamics_arch = net_arch.get("inverse_dynamics", planner_arch) if isinstance(net_arch, dict) else net_arch
        self.net_arch = net_arch
        self.planner_arch = planner_arch
        self.critic_arch = critic_arch
        self.activation_fn = activation_fn
        self.n_critics = n_critics
        self.planner_lr_schedule = planner_lr_schedule
        self.inverse_dynamics_lr_schedule = inverse_dynamics_lr_schedule
        self._build(lr_schedule)

    def _build(self, lr_schedule: Schedule) -> None:
        planner_features = self.make_features_extractor()
        self.state_planner = StatePlanner(
            self.observation_space,
            self.action_space,
            net_arch=self.planner_arch,
            features_extractor=planner_features,
            features_dim=planner_features.features_dim,
            activation_fn=self.activation_fn,
        )
        self.inverse_dynamics = InverseDynamics(
            self.state_planner.state_dim, get_action_dim(self.action_space), self.inverse_dynamics_arch, self.activation_fn
        )
        self.critic = self._make_critic()
        self.critic_target = self._make_critic()
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.critic_target.set_training_mode(False)
        self._mode_switched_modules = [
            self,
            *self.state_planner.modules(),
            *self.inverse_dynamics.modules(),
            *self.critic.modules(),
        ]

        planner_lr = (self.planner_lr_schedule or lr_schedule)(1)
        inverse_dynamics_lr = (self.inverse_dynamics_lr_schedule or lr_schedule)(1)
        self.state_planner.optimizer = self.optimizer_class(
            self.state_planner.parameters(),
            lr=planner_lr,
            **self.optimizer_kwargs,  # type: ignore[call-arg]
        )
        self.inverse_dynamics.optimizer = self.optimizer_class(
            self.inverse_dynamics.parameters(),
            lr=inverse_dynamics_lr,
            **self.optimizer_kwargs,  # type: ignore[call-arg]
        )
        self.critic.optimizer = self.optimizer_class(
            self.critic.parameters(),
            lr=lr_schedule(1),
            **self.optimizer_kwargs,  # type: ignore[call-arg]
        )

    def _make_critic(self) -> ContinuousCritic:
        features_extractor = self.make_features_extractor()
        return ContinuousCritic(
            self.observation_space,
            self.action_space,
            net_arch=self.critic_arch,
            features_extractor=features_extractor,
            features_dim=features_extractor.features_dim,
            activation_fn=self.activation_fn,
            normalize_images=False,
            n_critics=self.n_critics,
            share_features_extractor=False,
        )

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(
            net_arch=self.net_arch,
            activation_fn=self.activation_fn,
            n_critics=self.n_critics,
            lr_schedule=self._dummy_schedule,
            planner_lr_schedule=self._dummy_schedule,
            inverse_dynamics_lr_schedule=self._dummy_schedule,
            optimizer_class=self.optimizer_class,
            optimizer_kwargs=self.optimizer_kwargs,
            features_extractor_class=self.features_extractor_class,
            features_extractor_kwargs=self.features_extractor_kwargs,
        )
        return data

    @property
    def state_dim(self) -> int:
        """Size of the planner state."""
        return self.state_planner.state_dim

    @property
    def goal_slice(self) -> slice | None:
        """Slice of the planner state that is the achieved goal (the goal mapping ``phi``); None without goals."""
        if isinstance(self.observation_space, spaces.Dict) and "achieved_goal" in self.observation_space.spaces:
            goal_dim = int(self.observation_space["achieved_goal"].shape[0])
            return slice(self.state_dim - goal_dim, self.state_dim)
        return None

    def plan_and_act(self, obs: PyTorchObs, deterministic: bool = False) -> Plan:
        """
        Plan a next state ``s' ~ h(. | s, g)`` and act towards it with ``a ~ I(. | s, s')``.

        :param obs: preprocessed observation batch
        :param deterministic: use the means of the planner and of the inverse dynamics
        :return: the planner's distribution, the planned state, the squashed action in ``[-1, 1]`` and
            ``log I(a | s, s')`` (shape ``(batch,)``)
        """
        state, delta_mean, log_std, planned = self.state_planner.plan(obs, deterministic)
        actions, log_prob = self.inverse_dynamics(state, planned, deterministic=deterministic)
        return Plan(state, delta_mean, log_std, planned, actions, log_prob)

    def forward(self, obs: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self._predict(obs, deterministic=deterministic)

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        plan = self.plan_and_act(observation, deterministic)
        # Kept for the plan error that UDPO logs during rollouts
        self.last_planned_state = plan.planned_state
        return plan.actions

    def predict_next_state(self, observation: np.ndarray | dict[str, np.ndarray], deterministic: bool = True) -> np.ndarray:
        """
        The planner's landmark: the next planner state ``s'`` for an observation (batch), as a numpy array.

        The result lives in the space of the observation given (normalised, if the model was trained with
        ``VecNormalize`` and ``observation`` is normalised).
        """
        self.set_training_mode(False)
        obs_tensor, vectorized_env = self.obs_to_tensor(observation)
        with th.no_grad():
            planned = self.state_planner(obs_tensor, deterministic=deterministic).cpu().numpy()
        return planned if vectorized_env else planned[0]

    def set_training_mode(self, mode: bool) -> None:
        """
        Put the planner, the inverse dynamics and the critics in training or evaluation mode (the target critics stay in
        evaluation mode). A no-op when already in that mode: SB3 calls this at every env step and every update.
        """
        if mode == self.training:
            return
        # What nn.Module.train(mode) does to each module, without its per-call recursion and __setattr__ checks
        for module in self._mode_switched_modules:
            object.__setattr__(module, "training", mode)


MlpPolicy = UDPOPolicy


class MultiInputPolicy(UDPOPolicy):
    """
    UDPO policy for Dict goal observations (``observation``, ``achieved_goal``, ``desired_goal``).

    :param observation_space: Observation space
    :param action_space: Action space
    :param lr_schedule: Learning rate schedule
    :param features_extractor_class: Features extractor (``CombinedExtractor`` by default)
    :param kwargs: see :class:`UDPOPolicy`
    """

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
