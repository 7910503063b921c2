"""Policies of UDPO: the goal-conditioned state planner ``h``, the inverse dynamics ``I`` and twin Q critics."""

import functools
import math
from typing import Any, NamedTuple

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.policies import BaseModel, BasePolicy
from stable_baselines3.common.preprocessing import get_action_dim, get_flattened_obs_dim, is_image_space, preprocess_obs
from stable_baselines3.common.torch_layers import (
    BaseFeaturesExtractor,
    CombinedExtractor,
    FlattenExtractor,
    create_mlp,
    get_actor_critic_arch,
)
from stable_baselines3.common.type_aliases import PyTorchObs, Schedule
from torch import nn

from sb3_pilot.common.critics import EnsembleCritic
from sb3_pilot.common.distributions import (
    LOG_STD_MAX,
    LOG_STD_MIN,
    gaussian_log_prob,
    multivariate_gaussian_log_prob,
    reparameterised_log_prob,
    squashed_gaussian_log_prob,
    squashed_gaussian_sample,
)
from sb3_pilot.common.lean import set_training_flags
from sb3_pilot.optimizers import lean_optimizer_kwargs

#: Planner states are observations without this key (the target goal ``g`` conditions ``h``, it is not planned).
DESIRED_GOAL = "desired_goal"
#: The key whose value is the goal mapping ``phi(s)``: placed last in the planner state.
ACHIEVED_GOAL = "achieved_goal"
#: ``I`` fits buffer actions clamped to ``[-tanh(3), tanh(3)]`` (+-0.995): an action on the bound of the action space
#: (clipped exploration noise, a clipping controller) has no pre-squash value, and ``atanh(1 - 1.2e-7) = 8.3`` made those
#: actions dominate the fit (clipped Gaussian exploration noise could then stop UDPO learning).
ACTION_FIT_BOUND = math.tanh(3.0)
#: How the decoupled policy's ``log pi(a | s, g)`` is estimated for the entropy terms (see :class:`UDPOPolicy`)
ENTROPY_TERMS = ("inverse_dynamics", "linearised")
#: Added to the linearised policy's covariance (float64) so that its Cholesky factor exists when ``I`` is sure
COVARIANCE_JITTER = 1e-10
#: Why UDPO refuses gSDE.
NO_SDE = "UDPO does not support gSDE (use_sde=True): its action comes from the inverse dynamics, not from an SDE actor."


def planner_state_keys(observation_space: spaces.Space) -> tuple[str, ...]:
    """
    Keys of a Dict observation that form the planner state ``s``, in their order in ``s``: every key but
    ``desired_goal``, sorted, with ``achieved_goal`` last (so ``phi(s)`` is the tail of ``s``). Empty for other spaces
    (the whole observation is the state).

    :param observation_space: the observation space
    """
    if not isinstance(observation_space, spaces.Dict):
        return ()
    keys = sorted(key for key in observation_space.spaces if key not in (DESIRED_GOAL, ACHIEVED_GOAL))
    return (*keys, ACHIEVED_GOAL) if ACHIEVED_GOAL in observation_space.spaces else tuple(keys)


def check_observation_space(observation_space: spaces.Space) -> None:
    """
    Raise a ``ValueError`` naming the problem if UDPO cannot plan in ``observation_space``.

    The planner state is the flattened (one-hot for discrete spaces, as SB3 preprocesses them) observation, or for a
    Dict every entry but ``desired_goal``. The planner predicts it as a Gaussian vector, so no entry of it may be an
    image, and it may not be empty.

    :param observation_space: the observation space
    """
    if isinstance(observation_space, spaces.Dict):
        keys = planner_state_keys(observation_space)
        if not keys:
            raise ValueError(
                f"UDPO's state planner plans every observation entry but '{DESIRED_GOAL}', and there is none: "
                f"{observation_space}."
            )
        for key in keys:
            _check_plannable(observation_space[key], f"observation entry '{key}'")
    else:
        _check_plannable(observation_space, "observation space")


def _check_plannable(space: spaces.Space, what: str) -> None:
    if isinstance(space, (spaces.Dict, spaces.Tuple)):
        raise ValueError(f"UDPO's state planner cannot plan the nested {what} {space}: flatten it first.")
    if not isinstance(space, (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)):
        raise ValueError(f"UDPO's state planner cannot plan the {what} {space}: SB3 cannot preprocess it into a vector.")
    if isinstance(space, spaces.Box) and is_image_space(space, check_channels=False):
        raise ValueError(
            f"The {what} is an image ({space}): UDPO's state planner would have to predict the next image as a Gaussian "
            "over pixels, which it does not do. For image targets, train SAC + HER with sb3_pilot.PilotBonusWrapper and "
            "a goal planner distilled from a vector source."
        )


def planner_state_dim(observation_space: spaces.Space) -> int:
    """Size of the planner state ``s`` (see :func:`planner_state_keys`)."""
    keys = planner_state_keys(observation_space)
    if keys:
        return sum(int(get_flattened_obs_dim(observation_space[key])) for key in keys)  # type: ignore[index]
    return int(get_flattened_obs_dim(observation_space))


class PlannerDistribution(NamedTuple):
    """
    The state planner's distribution ``h(s' | s, g)`` at a batch of observations: a diagonal Gaussian over ``s' - s``.

    :param state: the planner state ``s`` of the observations
    :param delta_mean: mean of ``s' - s``
    :param delta_log_std: log standard deviation of ``s' - s``
    """

    state: th.Tensor
    delta_mean: th.Tensor
    delta_log_std: th.Tensor

    @property
    def mean(self) -> th.Tensor:
        """The mean planned next state ``E[s']``."""
        return self.state + self.delta_mean

    def sample(self, deterministic: bool = False) -> th.Tensor:
        """A reparameterised sample ``s' = s + mu + sigma * eps`` (paper eq. "repara"), or the mean."""
        if deterministic:
            return self.mean
        return self.mean + th.randn_like(self.delta_mean) * th.exp(self.delta_log_std)

    def log_prob(self, next_state: th.Tensor) -> th.Tensor:
        """``log h(s' | s, g)`` of next states ``s'``, shape ``(batch,)``."""
        return gaussian_log_prob(next_state - self.state, self.delta_mean, self.delta_log_std)


class Plan(NamedTuple):
    """
    One pass of the decoupled policy ``pi(a | s, g) = E_{s' ~ h(.|s, g)} [I(a | s, s')]``.

    :param distribution: the planner's distribution ``h(. | s, g)`` (it holds ``s``)
    :param planned_next_state: the planned next state ``s' ~ h(. | s, g)``
    :param actions: the squashed action ``a ~ I(. | s, s')`` in ``[-1, 1]``
    :param log_prob: the policy's ``log pi(a | s, g)`` as ``UDPOPolicy.entropy_term`` estimates it, shape ``(batch,)``
    """

    distribution: PlannerDistribution
    planned_next_state: th.Tensor
    actions: th.Tensor
    log_prob: th.Tensor

    @property
    def state(self) -> th.Tensor:
        """The planner state ``s`` the plan starts from."""
        return self.distribution.state


class StatePlanner(BaseModel):
    """
    Goal-conditioned state planner ``h(s' | s, g)`` (paper section 3.1): a diagonal Gaussian over the *change* of the
    planner state, reparameterised so that gradients reach ``h`` through the sampled plan,
    ``s' = s + mu(s, g) + sigma(s, g) * eps``. The network sees the whole observation, goals included.

    :param observation_space: Observation space
    :param action_space: Action space (unused by the planner, kept for SB3's model interface)
    :param net_arch: Hidden layer sizes
    :param features_extractor: Network that flattens (and concatenates) the observation
    :param features_dim: Number of features produced by ``features_extractor``
    :param activation_fn: Activation function
    :param normalize_images: Whether to divide image entries by 255 (only ``desired_goal`` may be an image)
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        net_arch: list[int],
        features_extractor: BaseFeaturesExtractor,
        features_dim: int,
        activation_fn: type[nn.Module] = nn.ReLU,
        normalize_images: bool = True,
    ):
        super().__init__(
            observation_space, action_space, features_extractor=features_extractor, normalize_images=normalize_images
        )
        self.net_arch = net_arch
        self.features_dim = features_dim
        self.activation_fn = activation_fn
        self.state_keys = planner_state_keys(observation_space)
        self.state_dim = planner_state_dim(observation_space)
        # One output layer for mean and log-std: fewer kernel launches on the hot path
        self.net = nn.Sequential(*create_mlp(features_dim, 2 * self.state_dim, net_arch, activation_fn))

    def planner_state(self, obs: PyTorchObs) -> th.Tensor:
        """
        Planner state ``s`` of an observation batch: its entries but ``desired_goal``, preprocessed as SB3's networks
        see them (float, one-hot for discrete entries), flattened and concatenated (see :func:`planner_state_keys`).
        """
        return self._flat_state(preprocess_obs(obs, self.observation_space, normalize_images=self.normalize_images))

    def _flat_state(self, preprocessed: PyTorchObs) -> th.Tensor:
        if isinstance(preprocessed, dict):
            return th.cat([preprocessed[key].flatten(1) for key in self.state_keys], dim=1)
        return preprocessed.flatten(1)

    def distribution(self, obs: PyTorchObs) -> PlannerDistribution:
        """
        :param obs: observation batch as tensors
        :return: the Gaussian ``h(. | s, g)``
        """
        # What BaseModel.extract_features does, keeping the preprocessed observation for the planner state
        preprocessed = preprocess_obs(obs, self.observation_space, normalize_images=self.normalize_images)
        delta_mean, log_std = self.net(self.features_extractor(preprocessed)).chunk(2, dim=-1)
        return PlannerDistribution(self._flat_state(preprocessed), delta_mean, th.clamp(log_std, LOG_STD_MIN, LOG_STD_MAX))

    def log_prob(self, obs: PyTorchObs, next_state: th.Tensor) -> th.Tensor:
        """
        ``log h(s' | s, g)`` of next planner states.

        :param obs: observation batch
        :param next_state: planner states ``s'`` (e.g. ``planner_state`` of the next observations)
        :return: log-likelihoods, shape ``(batch,)``
        """
        return self.distribution(obs).log_prob(next_state)

    def forward(self, obs: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        """Planned next state ``s'`` (the mean if ``deterministic``, else a reparameterised sample)."""
        return self.distribution(obs).sample(deterministic)

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
    (normalised) action that takes the planner state from ``s`` to ``s'``. Its input is ``[s, s' - s]``; it has its own
    optimizer (``optimizer``).

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
        """Mean and log-std (clamped as SAC's actor does) of the pre-squash Gaussian over actions."""
        mean, log_std = self.net(th.cat([state, next_state - state], dim=1)).chunk(2, dim=-1)
        return mean, th.clamp(log_std, LOG_STD_MIN, LOG_STD_MAX)

    def forward(self, state: th.Tensor, next_state: th.Tensor, deterministic: bool = False) -> tuple[th.Tensor, th.Tensor]:
        """Squashed action in ``[-1, 1]`` and its log-probability."""
        return squashed_gaussian_sample(*self.distribution_params(state, next_state), deterministic=deterministic)

    def log_prob(self, state: th.Tensor, next_state: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """
        ``log I(a | s, s')`` of buffer actions in ``[-1, 1]`` (the supervised loss is its negative), actions clamped to
        ``+-ACTION_FIT_BOUND``.
        """
        mean, log_std = self.distribution_params(state, next_state)
        return squashed_gaussian_log_prob(th.atanh(actions.clamp(-ACTION_FIT_BOUND, ACTION_FIT_BOUND)), mean, log_std)


class UDPOPolicy(BasePolicy):
    """
    Decoupled goal-conditioned policy ``pi(a | s, g) = E_{s' ~ h(.|s, g)} [I(a | s, s')]`` with twin Q critics
    (one :class:`~sb3_pilot.common.critics.EnsembleCritic`).

    Acting samples a plan ``s' ~ h(. | s, g)`` and then an action ``a ~ I(. | s, s')``. The marginal ``log pi(a | s, g)``
    of the entropy terms is intractable; ``entropy_term`` says how it is estimated:

    * ``"inverse_dynamics"`` (default): ``log I(a | s, s')`` at the sampled plan (as in DePO). ``I``'s spread is
      fitted to the buffer, and the planner's reaches the term only through where ``I`` is unsure, so the temperature
      has no hold on how widely the policy acts.
    * ``"linearised"``: ``I``'s mean linearised at the sampled plan, ``J = d mu_I / d s'`` (held fixed): the pre-squash
      action ``u = mu_I(s, s') + sigma_I eps_a`` deviates from ``mu_I(s, E[h])`` by about
      ``J sigma_h eps_h + sigma_I eps_a ~ N(0, J diag(sigma_h^2) J^T + diag(sigma_I^2))``, whose log-density (and the
      squashing's) is the estimate. The planner's spread ``sigma_h`` enters it, so the temperature controls how
      widely the policy acts, as SAC's does.

    ``last_plan_mean`` holds the planner's mean ``E[h(. | s, g)]`` of the last :meth:`predict`, which UDPO's plan
    error reuses instead of a second forward pass per env step.

    :param observation_space: Observation space (see :func:`check_observation_space`)
    :param action_space: Action space (Box)
    :param lr_schedule: Learning rate schedule of the critic (and of the planner if ``planner_lr_schedule`` is None)
    :param net_arch: Hidden layers: a list shared by all networks, or a dict with keys ``pi`` (planner),
        ``qf`` (critics) and optionally ``inverse_dynamics`` (defaults to ``pi``)
    :param activation_fn: Activation function
    :param features_extractor_class: Features extractor of the planner and critics
    :param features_extractor_kwargs: Keyword arguments for the features extractor
    :param normalize_images: Whether to divide image entries by 255 (only ``desired_goal`` may be an image)
    :param optimizer_class: Optimizer class
    :param optimizer_kwargs: Optimizer keyword arguments (except the learning rate); Adam is fused
        (``fused=True``) unless they say otherwise
    :param n_critics: Number of critic networks
    :param planner_lr_schedule: Learning rate schedule of the state planner (None: ``lr_schedule``)
    :param inverse_dynamics_lr_schedule: Learning rate schedule of the inverse dynamics (None: ``lr_schedule``)
    :param freeze_state_planner: hold the state planner fixed (a planner transferred from a source, see
        :meth:`load_state_planner`): UDPO then trains only the inverse dynamics (the policy reads neither the
        critics nor the temperature, which exist to train the planner, so they stay untrained)
    :param use_sde: must be False (accepted because SAC writes it into the ``policy_kwargs`` dict it is given)
    :param entropy_term: how ``log pi(a | s, g)`` is estimated, one of :data:`ENTROPY_TERMS` (UDPO sets it from its
        own ``entropy_term``)
    """

    state_planner: StatePlanner
    inverse_dynamics: InverseDynamics
    critic: EnsembleCritic
    critic_target: EnsembleCritic
    last_plan_mean: th.Tensor | None = None

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Box,
        lr_schedule: Schedule,
        net_arch: list[int] | dict[str, list[int]] | None = None,
        activation_fn: type[nn.Module] = nn.ReLU,
        features_extractor_class: type[BaseFeaturesExtractor] = FlattenExtractor,
        features_extractor_kwargs: dict[str, Any] | None = None,
        normalize_images: bool = True,
        optimizer_class: type[th.optim.Optimizer] = th.optim.Adam,
        optimizer_kwargs: dict[str, Any] | None = None,
        n_critics: int = 2,
        planner_lr_schedule: Schedule | None = None,
        inverse_dynamics_lr_schedule: Schedule | None = None,
        freeze_state_planner: bool = False,
        use_sde: bool = False,
        entropy_term: str = "inverse_dynamics",
    ):
        if use_sde:
            raise ValueError(NO_SDE)
        if entropy_term not in ENTROPY_TERMS:
            raise ValueError(f"entropy_term must be one of {ENTROPY_TERMS}, got {entropy_term!r}.")
        check_observation_space(observation_space)
        super().__init__(
            observation_space,
            action_space,
            features_extractor_class,
            features_extractor_kwargs,
            optimizer_class=optimizer_class,
            optimizer_kwargs=lean_optimizer_kwargs(optimizer_class, optimizer_kwargs),
            squash_output=True,
            normalize_images=normalize_images,
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
        self.freeze_state_planner = freeze_state_planner
        self.entropy_term = entropy_term
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
            normalize_images=self.normalize_images,
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
        if self.freeze_state_planner:
            self.state_planner.requires_grad_(False)

        self.state_planner.optimizer = self.optimizer_class(
            self.state_planner.parameters(),
            lr=(self.planner_lr_schedule or lr_schedule)(1),
            **self.optimizer_kwargs,  # type: ignore[call-arg]
        )
        self.inverse_dynamics.optimizer = self.optimizer_class(
            self.inverse_dynamics.parameters(),
            lr=(self.inverse_dynamics_lr_schedule or lr_schedule)(1),
            **self.optimizer_kwargs,  # type: ignore[call-arg]
        )
        self.critic.optimizer = self.optimizer_class(
            self.critic.parameters(),
            lr=lr_schedule(1),
            **self.optimizer_kwargs,  # type: ignore[call-arg]
        )

    def _make_critic(self) -> EnsembleCritic:
        features_extractor = self.make_features_extractor()
        return EnsembleCritic(
            self.observation_space,
            self.action_space,
            net_arch=self.critic_arch,
            features_extractor=features_extractor,
            features_dim=features_extractor.features_dim,
            activation_fn=self.activation_fn,
            normalize_images=self.normalize_images,
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
            freeze_state_planner=self.freeze_state_planner,
            entropy_term=self.entropy_term,
        )
        return data

    @property
    def state_dim(self) -> int:
        """Size of the planner state."""
        return self.state_planner.state_dim

    @property
    def goal_slice(self) -> slice | None:
        """Slice of the planner state that is the achieved goal (the goal mapping ``phi``); None without goals."""
        if isinstance(self.observation_space, spaces.Dict) and ACHIEVED_GOAL in self.observation_space.spaces:
            goal_dim = get_flattened_obs_dim(self.observation_space[ACHIEVED_GOAL])
            return slice(self.state_dim - goal_dim, self.state_dim)
        return None

    def load_state_planner(self, state_dict: dict[str, th.Tensor], source: str = "the source") -> None:
        """
        Take the weights of another policy's state planner (PILoT's transfer across action spaces, paper section 3.3).
        The planner stays frozen if this policy was built with ``freeze_state_planner=True``.

        :param state_dict: ``state_planner.state_dict()`` of the source policy
        :param source: what the weights come from, for error messages
        :raises ValueError: if the source planner has another architecture (layer names or shapes)
        """
        source_shapes = {name: tuple(value.shape) for name, value in state_dict.items()}
        target_shapes = {name: tuple(value.shape) for name, value in self.state_planner.state_dict().items()}
        if source_shapes != target_shapes:
            raise ValueError(
                f"The state planner of {source} has another architecture than this policy's: keep its net_arch and "
                f"features extractor in policy_kwargs (source {source_shapes}, target {target_shapes})."
            )
        self.state_planner.load_state_dict(state_dict)

    def plan_and_act(self, obs: PyTorchObs, deterministic: bool = False) -> Plan:
        """
        Plan a next state ``s' ~ h(. | s, g)`` and act towards it with ``a ~ I(. | s, s')``.

        :param obs: observation batch as tensors
        :param deterministic: use the means of the planner and of the inverse dynamics (``log_prob`` is then
            ``log I``'s, whatever ``entropy_term``)
        :return: the plan, its action and ``log pi(a | s, g)`` (see ``entropy_term``)
        """
        distribution = self.state_planner.distribution(obs)
        planned_next_state = distribution.sample(deterministic)
        mean, log_std = self.inverse_dynamics.distribution_params(distribution.state, planned_next_state)
        pre_squash_log_prob = (
            reparameterised_log_prob
            if self.entropy_term == "inverse_dynamics"
            else functools.partial(self.linearised_log_prob, distribution, planned_next_state)
        )
        actions, log_prob = squashed_gaussian_sample(mean, log_std, deterministic, pre_squash_log_prob)
        return Plan(distribution, planned_next_state, actions, log_prob)

    def linearised_log_prob(
        self, distribution: PlannerDistribution, planned_next_state: th.Tensor, noise: th.Tensor, log_std: th.Tensor
    ) -> th.Tensor:
        """
        ``log pi(u | s, g)`` of a pre-squash action ``u = mu_I(s, s') + sigma_I * noise`` drawn at a reparameterised
        plan ``s'``, with ``I``'s mean linearised at ``s'`` (``entropy_term="linearised"``): the density of
        ``J sigma_h eps_h + sigma_I noise`` under ``N(0, J diag(sigma_h^2) J^T + diag(sigma_I^2))``, in float64 (float32
        on MPS).

        :param distribution: the planner's ``h(. | s, g)``
        :param planned_next_state: the plan ``s'`` drawn from it
        :param noise: the standard normal draw ``eps_a`` of the action
        :param log_std: ``log sigma_I(s, s')``
        :return: log-densities, shape ``(batch,)``
        """
        dtype = th.float32 if log_std.device.type == "mps" else th.float64  # MPS has no float64
        planner_std = th.exp(distribution.delta_log_std)
        planner_noise = ((planned_next_state - distribution.mean) / planner_std).detach().to(dtype)
        planner_std = planner_std.to(dtype)
        jacobian = self.inverse_dynamics_jacobian(distribution.state, planned_next_state)
        spread = jacobian.to(dtype) * planner_std.unsqueeze(1)  # J diag(sigma_h)
        action_std = th.exp(log_std).to(dtype)
        deviation = (spread @ planner_noise.unsqueeze(-1)).squeeze(-1) + action_std * noise.to(dtype)
        jitter = COVARIANCE_JITTER * th.eye(action_std.shape[-1], dtype=dtype, device=action_std.device)
        covariance = spread @ spread.transpose(1, 2) + th.diag_embed(action_std**2) + jitter
        try:
            return multivariate_gaussian_log_prob(deviation, covariance).to(log_std.dtype)
        except th.linalg.LinAlgError as error:  # positive-definite by construction unless an entry is NaN
            raise FloatingPointError(
                "UDPO diverged: the linearised entropy term's action covariance J diag(sigma_h^2) J^T + diag(sigma_I^2) "
                "holds NaN, so the state planner or the inverse dynamics output NaN. A temperature runaway from SB3's "
                "initial temperature of 1 can cause it: watch train/ent_coef and rollout/plan_error, and try a lower "
                "initial temperature (ent_coef='auto_0.1'; measurements in docs/results/sources.md)."
            ) from error

    def inverse_dynamics_jacobian(self, state: th.Tensor, next_state: th.Tensor) -> th.Tensor:
        """
        ``J = d mu_I(s, s') / d s'``, the Jacobian of the inverse dynamics' pre-squash mean in the planned state, held
        fixed (no gradient flows through it): ``action_dim`` copies of the batch through ``I`` and one backward pass.

        :param state: planner states ``s``, shape ``(batch, state_dim)``
        :param next_state: planned states ``s'``, same shape
        :return: shape ``(batch, action_dim, state_dim)``
        """
        batch, action_dim = next_state.shape[0], self.inverse_dynamics.action_dim
        with th.enable_grad():
            copies = next_state.detach().repeat_interleave(action_dim, dim=0).requires_grad_(True)
            mean, _ = self.inverse_dynamics.distribution_params(state.detach().repeat_interleave(action_dim, dim=0), copies)
            selector = th.eye(action_dim, dtype=mean.dtype, device=mean.device).repeat(batch, 1)
            (jacobian,) = th.autograd.grad(mean, copies, grad_outputs=selector)
        return jacobian.view(batch, action_dim, -1)

    def forward(self, obs: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        return self._predict(obs, deterministic=deterministic)

    def _predict(self, observation: PyTorchObs, deterministic: bool = False) -> th.Tensor:
        # Acting needs no log-probability: the plan and I's action only
        distribution = self.state_planner.distribution(observation)
        self.last_plan_mean = distribution.mean
        actions, _ = self.inverse_dynamics(distribution.state, distribution.sample(deterministic), deterministic)
        return actions

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
        set_training_flags(self._mode_switched_modules, mode)


MlpPolicy = UDPOPolicy


class MultiInputPolicy(UDPOPolicy):
    """
    UDPO policy for Dict observations (goal envs: ``observation``, ``achieved_goal``, ``desired_goal``).

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
        if not isinstance(observation_space, spaces.Dict):
            raise ValueError(
                f"MultiInputPolicy needs a Dict observation space, got {observation_space}: use 'MlpPolicy' for it."
            )
        super().__init__(
            observation_space, action_space, lr_schedule, features_extractor_class=features_extractor_class, **kwargs
        )
