"""Universal Decoupled Policy Optimisation (UDPO), the pre-training stage of PILoT (paper section 3.1)."""

from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import NStepReplayBuffer, ReplayBuffer
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import (
    DictReplayBufferSamples,
    GymEnv,
    MaybeCallback,
    PyTorchObs,
    ReplayBufferSamples,
    Schedule,
)
from stable_baselines3.common.utils import (
    FloatSchedule,
    get_parameters_by_name,
    obs_as_tensor,
    update_learning_rate,
)
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer
from torch.nn import functional as F

from sb3_pilot.common.cuda_graph import CudaGraphUpdate
from sb3_pilot.common.lean import LeanSACSteps, LossRecorder, check_update_settings, record_losses
from sb3_pilot.common.utils import check_number
from sb3_pilot.udpo.policies import (
    ENTROPY_TERMS,
    NO_SDE,
    InverseDynamics,
    MlpPolicy,
    MultiInputPolicy,
    Plan,
    StatePlanner,
    UDPOPolicy,
    check_observation_space,
)

SelfUDPO = TypeVar("SelfUDPO", bound="UDPO")

#: Options of earlier versions (``forward_dynamics``: of ``policy_kwargs``): the version that removed each, its default
#: then (a model saved with it loads, the option ignored) and what UDPO does instead
REMOVED_OPTIONS: dict[str, tuple[str, Any, str]] = {
    "planner_nll_beta": ("0.2", 0.0, "the likelihood term is the paper's -log h(s' | s, g) (beta 0)"),
    "plan_target": (
        "0.2",
        "buffer",
        "the likelihood term fits the buffer's next state, the paper's implementation (the default then)",
    ),
    "forward_dynamics": ("0.2", False, "the policy has no forward dynamics model, which served plan_target='policy'"),
}


def removed_option_message(name: str, value: Any) -> str:
    """
    :param name: a key of :data:`REMOVED_OPTIONS`
    :param value: the value given (or saved)
    :return: what to tell who names the option
    """
    version, default, instead = REMOVED_OPTIONS[name]
    return (
        f"{name}={value!r}: {name} was removed in sb3-pilot {version}: {instead}. Remove it from the call, the "
        f"hyperparameters or the YAML (a model saved with {name}={default!r} loads, the option ignored)."
    )


def refuse_removed_options(owner: str, options: dict[str, Any]) -> None:
    """
    Refuse keyword arguments that UDPO does not take: the removed options (:data:`REMOVED_OPTIONS`) by name and
    version, any other as Python refuses an unexpected keyword.

    :param owner: the class name, for the message
    :param options: the unexpected keyword arguments
    :raises TypeError: if there is any
    """
    for name, value in options.items():
        if name in REMOVED_OPTIONS:
            raise TypeError(removed_option_message(name, value))
        raise TypeError(f"{owner}.__init__() got an unexpected keyword argument {name!r}")


class UDPO(LeanSACSteps, OffPolicyAlgorithm):
    """
    Universal Decoupled Policy Optimisation, PILoT's pre-training algorithm (Liu et al., ICLR 2023, section 3.1).

    The goal-conditioned policy is decoupled as ``pi(a | s, g) = E_{s' ~ h(s' | s, g)} [I(a | s, s')]`` into a state
    planner ``h`` (``policy.state_planner``) and an inverse dynamics ``I`` (``policy.inverse_dynamics``); the twin
    critics and the temperature are SAC's, trained with :class:`~sb3_pilot.sac.LeanSAC`'s steps. ``I`` is fitted by
    maximum likelihood on buffer transitions ``(s, s', a)`` every ``Delta`` gradient steps and held fixed in between;
    ``h`` minimises SAC's actor loss through the frozen ``I`` plus ``lambda`` times ``-log h(s' | s, g)`` of the
    buffer's next state. The planner state ``s`` is ``observation`` followed by ``achieved_goal`` (Dict observations),
    so the goal mapping ``phi`` is its tail (``policy.goal_slice``). No gSDE, no n-step returns, no image entries in
    the planner state. Logs SAC's losses, ``train/planner_nll``, ``train/planner_loss``,
    ``train/inverse_dynamics_loss`` and ``rollout/plan_error`` (the paper's pred-real MSE). The measurements behind
    the defaults: ``docs/results/sources.md``. The parameters not listed below are SB3 ``SAC``'s, same meaning and
    defaults. Example (``HerReplayBuffer`` from ``stable_baselines3``):

    .. code-block:: python

        model = UDPO("MultiInputPolicy", "Pilot/Maze2D-v0", replay_buffer_class=HerReplayBuffer).learn(20_000)
        landmarks = model.predict_next_state(model.get_env().reset())  # E[h(. | s, g)] per env

    :param policy: ``"MultiInputPolicy"`` (Dict goal envs), ``"MlpPolicy"`` (goal-free planner) or a policy class
    :param env: the environment to learn from (a Gymnasium ID, an env or a VecEnv)
    :param learning_rate: learning rate of the critics and the temperature (a float or a schedule)
    :param buffer_size: size of the replay buffer (>= 1)
    :param batch_size: minibatch size of each gradient step (>= 1)
    :param n_steps: must be 1: ``I`` and ``h`` fit one-step transitions (accepted for SAC's signature)
    :param use_sde: must be False: the action comes from ``I`` (accepted for SAC's signature)
    :param planner_coef: ``lambda``, weight of the planner's ``-log h(s' | s, g)`` (the paper's 1e-2 is stronger)
    :param entropy_term: how the entropy terms estimate ``log pi(a | s, g)``: ``"inverse_dynamics"`` (``log I`` at
        the sampled plan, DePO's) or ``"linearised"`` (``I`` linearised at the plan, so that ``h``'s spread enters it;
        for tasks where a detour must be found), see :class:`~sb3_pilot.udpo.UDPOPolicy`
    :param inverse_dynamics_interval: ``Delta``, gradient steps between two refits of ``I`` (paper: 1500, Fetch 200)
    :param inverse_dynamics_gradient_steps: supervised gradient steps of each refit of ``I``
    :param planner_learning_rate: learning rate of ``h`` (None: ``learning_rate``)
    :param inverse_dynamics_learning_rate: learning rate of ``I`` (None: ``learning_rate``)
    :param cuda_graphs: on CUDA, replay the gradient step (critics, ``h``, temperature, target update) as CUDA graphs,
        ``I``'s refits eager between them: ``LeanSAC``'s switch, same semantics and fallbacks, plus one for
        ``entropy_term="linearised"``
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy,
        "MultiInputPolicy": MultiInputPolicy,
    }
    policy: UDPOPolicy
    state_planner: StatePlanner
    inverse_dynamics: InverseDynamics

    def __init__(
        self,
        policy: str | type[UDPOPolicy],
        env: GymEnv | str,
        learning_rate: float | Schedule = 3e-4,
        buffer_size: int = 1_000_000,
        learning_starts: int = 100,
        batch_size: int = 256,
        tau: float = 0.005,
        gamma: float = 0.99,
        train_freq: int | tuple[int, str] = 1,
        gradient_steps: int = 1,
        action_noise: ActionNoise | None = None,
        replay_buffer_class: type[ReplayBuffer] | None = None,
        replay_buffer_kwargs: dict[str, Any] | None = None,
        optimize_memory_usage: bool = False,
        n_steps: int = 1,
        ent_coef: str | float = "auto",
        target_update_interval: int = 1,
        target_entropy: str | float = "auto",
        use_sde: bool = False,
        planner_coef: float = 1e-4,
        entropy_term: str = "inverse_dynamics",
        inverse_dynamics_interval: int = 1500,
        inverse_dynamics_gradient_steps: int = 50,
        planner_learning_rate: float | Schedule | None = None,
        inverse_dynamics_learning_rate: float | Schedule | None = 1e-4,
        stats_window_size: int = 100,
        tensorboard_log: str | None = None,
        policy_kwargs: dict[str, Any] | None = None,
        verbose: int = 0,
        seed: int | None = None,
        device: th.device | str = "auto",
        cuda_graphs: bool = False,
        _init_setup_model: bool = True,
        **removed_options: Any,
    ):
        removed_policy_options = {name: value for name, value in (policy_kwargs or {}).items() if name in REMOVED_OPTIONS}
        refuse_removed_options(type(self).__name__, {**removed_options, **removed_policy_options})
        if use_sde:
            raise ValueError(NO_SDE)
        check_update_settings(buffer_size, batch_size, tau, gamma)
        check_number("planner_coef (lambda)", planner_coef, minimum=0)
        if entropy_term not in ENTROPY_TERMS:
            raise ValueError(f"entropy_term must be one of {ENTROPY_TERMS}, got {entropy_term!r}.")
        for name, rate in (
            ("learning_rate", learning_rate),
            ("planner_learning_rate", planner_learning_rate),
            ("inverse_dynamics_learning_rate", inverse_dynamics_learning_rate),
        ):
            if rate is not None and not callable(rate):
                check_number(name, rate, minimum=0, strict=True)
        check_number("gamma", gamma, minimum=0)
        check_number("tau", tau, minimum=0)
        check_number("inverse_dynamics_interval (Delta)", inverse_dynamics_interval, minimum=1, integer=True)
        check_number("inverse_dynamics_gradient_steps", inverse_dynamics_gradient_steps, minimum=1, integer=True)
        no_n_step = "UDPO fits its inverse dynamics and state planner to one-step transitions s -> s'"
        if n_steps != 1:
            raise ValueError(f"n_steps={n_steps}: {no_n_step}, which n-step returns would replace by n-step ones.")
        if isinstance(replay_buffer_class, type) and issubclass(replay_buffer_class, NStepReplayBuffer):
            raise ValueError(f"{replay_buffer_class.__name__}: {no_n_step}, but its next observations are n steps ahead.")
        super().__init__(
            policy,
            env,
            learning_rate,
            buffer_size,
            learning_starts,
            batch_size,
            tau,
            gamma,
            train_freq,
            gradient_steps,
            action_noise,
            replay_buffer_class=replay_buffer_class,
            replay_buffer_kwargs=replay_buffer_kwargs,
            optimize_memory_usage=optimize_memory_usage,
            policy_kwargs=policy_kwargs,
            stats_window_size=stats_window_size,
            tensorboard_log=tensorboard_log,
            verbose=verbose,
            device=device,
            seed=seed,
            sde_support=False,
            support_multi_env=True,
        )
        self.target_entropy = target_entropy
        self.log_ent_coef: th.Tensor | None = None
        self.ent_coef = ent_coef
        self.target_update_interval = target_update_interval
        self.ent_coef_optimizer: th.optim.Adam | None = None
        self.planner_coef = planner_coef
        self.entropy_term = entropy_term
        self.inverse_dynamics_interval = inverse_dynamics_interval
        self.inverse_dynamics_gradient_steps = inverse_dynamics_gradient_steps
        self.planner_learning_rate = planner_learning_rate
        self.inverse_dynamics_learning_rate = inverse_dynamics_learning_rate
        self.cuda_graphs = cuda_graphs
        self._plan_errors: list[th.Tensor] = []
        self._rollout_plan_mean: th.Tensor | None = None

        if _init_setup_model:
            self._setup_model()

    def _setup_model(self) -> None:
        self._drop_removed_options()
        if not isinstance(self.action_space, spaces.Box):
            raise ValueError(
                "UDPO needs a continuous (Box) action space, its inverse dynamics being a squashed Gaussian; "
                f"got {self.action_space}."
            )
        check_observation_space(self.observation_space)
        uses_her = isinstance(self.replay_buffer_class, type) and issubclass(self.replay_buffer_class, HerReplayBuffer)
        goal_keys = set(self.observation_space.spaces) if isinstance(self.observation_space, spaces.Dict) else set()
        if uses_her and not {"achieved_goal", "desired_goal"} <= goal_keys:
            raise ValueError(
                "HerReplayBuffer needs a Dict observation with 'achieved_goal' and 'desired_goal' entries "
                f"(the achieved goal is also the planner's goal mapping phi), got {self.observation_space}."
            )
        self.planner_lr_schedule = FloatSchedule(
            self.learning_rate if self.planner_learning_rate is None else self.planner_learning_rate
        )
        self.inverse_dynamics_lr_schedule = FloatSchedule(
            self.learning_rate if self.inverse_dynamics_learning_rate is None else self.inverse_dynamics_learning_rate
        )
        self._use_lean_her()
        self.policy_kwargs = {
            **self.policy_kwargs,
            "planner_lr_schedule": self.planner_lr_schedule,
            "inverse_dynamics_lr_schedule": self.inverse_dynamics_lr_schedule,
            "entropy_term": self.entropy_term,
        }
        super()._setup_model()
        self._create_aliases()
        self.batch_norm_stats = get_parameters_by_name(self.critic, ["running_"])
        self.batch_norm_stats_target = get_parameters_by_name(self.critic_target, ["running_"])
        if self.target_entropy == "auto":
            self.target_entropy = float(-np.prod(self.action_space.shape).astype(np.float32))  # type: ignore[union-attr]
        else:
            self.target_entropy = float(self.target_entropy)

        if isinstance(self.ent_coef, str) and self.ent_coef.startswith("auto"):
            init_value = float(self.ent_coef.split("_")[1]) if "_" in self.ent_coef else 1.0
            if init_value <= 0.0:
                raise ValueError(f"The initial value of ent_coef must be > 0, got {init_value}.")
            self.log_ent_coef = th.log(th.ones(1, device=self.device) * init_value).requires_grad_(True)
            self.ent_coef_optimizer = th.optim.Adam([self.log_ent_coef], lr=self.lr_schedule(1))
        else:
            self.ent_coef_tensor = th.tensor(float(self.ent_coef), device=self.device)
        self._cuda_graph_update = (
            CudaGraphUpdate.for_model(self, self._optimizers(), self._capture_fallback_reason()) if self.cuda_graphs else None
        )

    def _optimizers(self) -> list[th.optim.Optimizer]:
        """The optimizers of a gradient step: the critics', the state planner's and the temperature's (if learnt)."""
        optimizers = [self.critic.optimizer, self.state_planner.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers.append(self.ent_coef_optimizer)
        return optimizers

    def _capture_fallback_reason(self) -> str | None:
        """UDPO's own reason not to capture its gradient step (``cuda_graphs``), if any."""
        if self.entropy_term == "linearised":
            return "entropy_term='linearised' checks its Cholesky factorisation on the host"
        return None

    def _drop_removed_options(self) -> None:
        """
        The removed options a loaded model's data sets (SB3's ``load`` writes them before ``_setup_model``): ignored at
        the value they had by default, refused with the removal's message otherwise.
        """
        for name, (_, default, _) in REMOVED_OPTIONS.items():
            for saved in (self.__dict__, self.policy_kwargs):
                value = saved.pop(name, default)
                if value != default:
                    raise ValueError(removed_option_message(name, value))

    def _create_aliases(self) -> None:
        self.state_planner = self.policy.state_planner
        self.inverse_dynamics = self.policy.inverse_dynamics
        self.critic = self.policy.critic
        self.critic_target = self.policy.critic_target
        self._planner_parameters = list(self.state_planner.parameters())
        self._critic_parameters = list(self.critic.parameters())
        self._critic_target_parameters = list(self.critic_target.parameters())

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        self.policy.set_training_mode(True)
        # h follows its own schedule
        self._update_learning_rate([opt for opt in self._optimizers() if opt is not self.state_planner.optimizer])
        update_learning_rate(self.state_planner.optimizer, self.planner_lr_schedule(self._current_progress_remaining))

        def refit_inverse_dynamics(gradient_step: int) -> None:
            # UDPO: I is refitted before the policy update that follows it (paper section 3.1, Algorithm 1). With
            # cuda_graphs it runs eagerly between two replays, not as a graph of its own: it runs once per Delta steps
            # (its launches cost little), reads its loss on the host, and its optimizer updates I's parameters in place,
            # where the captured step reads them, so the replays that follow use the refitted I
            if (self._n_updates + gradient_step) % self.inverse_dynamics_interval == 0:
                self.train_inverse_dynamics(self.inverse_dynamics_gradient_steps, batch_size)

        if self.policy.freeze_state_planner:
            # A frozen h (a planner transferred from a source): pi(a | s, g) = I(a | s, h(s' | s, g)) reads neither the
            # critics nor the temperature, which exist to train h, so they are left as they are
            for gradient_step in range(gradient_steps):
                refit_inverse_dynamics(gradient_step)
        else:
            self._run_gradient_steps(gradient_steps, batch_size, before_step=refit_inverse_dynamics)

        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")

    def _gradient_step(self, replay_data: DictReplayBufferSamples | ReplayBufferSamples, losses: LossRecorder) -> None:
        """
        One step of the temperature, the critics and the state planner ``h`` on a batch (the target update and ``I``'s
        refits excluded): pure tensor code, without host reads, which a CUDA graph captures (``cuda_graphs=True``).

        :param replay_data: the batch
        :param losses: where the losses are logged (a :class:`~sb3_pilot.common.lean.LossRecorder`, or the device sums
            of a captured step)
        """
        # Action of the decoupled policy: a ~ I(. | s, s') at a reparameterised plan s' = h(eps; s, g), I held fixed
        plan = self.policy.plan_and_act(replay_data.observations)
        log_prob = plan.log_prob.reshape(-1, 1)

        # Entropy coefficient (temperature) loss, log pi as entropy_term estimates it
        ent_coef = self._entropy_coef_step(log_prob, losses)

        # Critic loss (SAC's), the next action a' ~ I(. | s', s''), s'' ~ h(. | s', g)
        with th.no_grad():
            next_plan = self.policy.plan_and_act(replay_data.next_observations)
        target_q_values = self._target_q_values(replay_data, next_plan.actions, next_plan.log_prob, ent_coef)
        self._critic_step(replay_data.observations, replay_data.actions, target_q_values, losses)

        # Planner loss (section 3.1): the DePG actor loss through the frozen I and critics, plus lambda times the
        # planner's negative log-likelihood of the buffer's next state, gradients for the planner's parameters only
        actor_loss = self._actor_loss(replay_data.observations, plan.actions, log_prob, ent_coef, losses)
        planner_nll = self.planner_nll(plan, replay_data.next_observations)
        planner_loss = actor_loss + self.planner_coef * planner_nll
        losses.add("planner_nll", planner_nll)
        losses.add("planner_loss", planner_loss)
        self.state_planner.optimizer.zero_grad()
        planner_loss.backward(inputs=self._planner_parameters)
        self.state_planner.optimizer.step()

    def planner_nll(self, plan: Plan, next_observations: PyTorchObs) -> th.Tensor:
        """
        The planner's likelihood term, the paper's constraint ``max E_{(s, s')} [h(s' | s, g)]``: the mean of
        ``-log h(s' | s, g)`` over a batch of buffer transitions ``s -> s'``.

        :param plan: the decoupled policy's pass at the batch's observations ``s`` (it holds ``h(. | s, g)``)
        :param next_observations: the observations ``s'`` the transitions reached
        :return: the mean negative log-likelihood, a scalar tensor
        """
        return -plan.distribution.log_prob(self.state_planner.planner_state(next_observations)).mean()

    def train_inverse_dynamics(self, gradient_steps: int, batch_size: int) -> float:
        """
        Refit the inverse dynamics ``I(a | s, s')`` by maximum likelihood on buffer transitions ``(s, s', a)``
        (paper eq. "inverse-dynamics"). Only ``policy.inverse_dynamics`` changes.

        The transitions of all steps are drawn in one replay-buffer call (goals play no part in ``I``,
        so HER relabelling is irrelevant here) and split into ``gradient_steps`` minibatches.

        :param gradient_steps: number of supervised gradient steps
        :param batch_size: minibatch size
        :return: mean negative log-likelihood over the steps
        """
        self.policy.set_training_mode(True)
        update_learning_rate(
            self.inverse_dynamics.optimizer, self.inverse_dynamics_lr_schedule(self._current_progress_remaining)
        )
        replay_data = self.replay_buffer.sample(gradient_steps * batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
        states = self.state_planner.planner_state(replay_data.observations).split(batch_size)
        next_states = self.state_planner.planner_state(replay_data.next_observations).split(batch_size)
        losses = th.zeros(gradient_steps, device=self.device)
        for step, (state, next_state, actions) in enumerate(
            zip(states, next_states, replay_data.actions.split(batch_size), strict=True)
        ):
            loss = -self.inverse_dynamics.log_prob(state, next_state, actions).mean()
            self.inverse_dynamics.optimizer.zero_grad()
            loss.backward()
            self.inverse_dynamics.optimizer.step()
            losses[step] = loss.detach()
        mean_loss = losses.mean().item()
        record_losses(self.logger, {"inverse_dynamics_loss": mean_loss})
        return mean_loss

    def _store_transition(
        self,
        replay_buffer: ReplayBuffer,
        buffer_action: np.ndarray,
        new_obs: np.ndarray | dict[str, np.ndarray],
        reward: np.ndarray,
        dones: np.ndarray,
        infos: list[dict[str, Any]],
    ) -> None:
        self._plan_errors.append(
            self.plan_error(
                self._last_obs,  # type: ignore[arg-type]
                self._reached_observation(new_obs, dones, infos),
                planned=self._rollout_plan_mean,
            )
        )
        super()._store_transition(replay_buffer, buffer_action, new_obs, reward, dones, infos)

    def _sample_action(
        self, learning_starts: int, action_noise: ActionNoise | None = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        # The planner's mean at the acting forward pass, for this step's plan error (None for warm-up's random actions)
        self.policy.last_plan_mean = None
        actions, buffer_actions = super()._sample_action(learning_starts, action_noise, n_envs)
        self._rollout_plan_mean = self.policy.last_plan_mean
        return actions, buffer_actions

    @staticmethod
    def _reached_observation(
        new_obs: np.ndarray | dict[str, np.ndarray], dones: np.ndarray, infos: list[dict[str, Any]]
    ) -> np.ndarray | dict[str, np.ndarray]:
        """The observations the last step reached: ``new_obs``, but the terminal observation where an episode ended."""
        ended = [idx for idx, done in enumerate(dones) if done and infos[idx].get("terminal_observation") is not None]
        if not ended:
            return new_obs
        if isinstance(new_obs, dict):
            reached = {key: np.array(value) for key, value in new_obs.items()}
            for idx in ended:
                for key in reached:
                    reached[key][idx] = infos[idx]["terminal_observation"][key]
            return reached
        reached_array = np.array(new_obs)
        for idx in ended:
            reached_array[idx] = infos[idx]["terminal_observation"]
        return reached_array

    def plan_error(
        self,
        observations: np.ndarray | dict[str, np.ndarray],
        next_observations: np.ndarray | dict[str, np.ndarray],
        planned: th.Tensor | None = None,
    ) -> th.Tensor:
        """
        The paper's "pred-real-mse" of transitions: mean squared error, per state dimension and transition, between
        the planner's mean next state ``E[h(. | s, g)]`` and the reached planner state ``s'``.

        :param observations: batch of observations ``s`` (as the policy sees them)
        :param next_observations: the batch of observations reached from them
        :param planned: ``E[h(. | s, g)]`` if already computed (by the acting forward pass), else computed here
        :return: the mean squared error, a scalar tensor
        """
        with th.no_grad():
            planner = self.state_planner
            if planned is None:
                planned = planner.distribution(obs_as_tensor(observations, self.device)).mean
            reached = planner.planner_state(obs_as_tensor(next_observations, self.device))
            return F.mse_loss(planned, reached)

    def dump_logs(self) -> None:
        if self._plan_errors:
            self.logger.record("rollout/plan_error", th.stack(self._plan_errors).mean().item())
            self._plan_errors = []
        super().dump_logs()

    def predict_next_state(self, observation: np.ndarray | dict[str, np.ndarray], deterministic: bool = True) -> np.ndarray:
        """
        The planner's landmark: the next planner state ``s' ~ h(. | s, g)`` for an observation (or a batch), the
        plan, not where the policy's action for it leads (which ``sb3_pilot.distill_goal_planner`` distils by default).

        :param observation: an observation as the policy sees it (normalised if trained with ``VecNormalize``)
        :param deterministic: return the planner's mean instead of a sample
        :return: the planned next state (``observation`` + ``achieved_goal`` for Dict observations)
        """
        return self.policy.predict_next_state(observation, deterministic=deterministic)

    def learn(
        self: SelfUDPO,
        total_timesteps: int,
        callback: MaybeCallback = None,
        log_interval: int = 4,
        tb_log_name: str = "UDPO",
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> SelfUDPO:
        return super().learn(total_timesteps, callback, log_interval, tb_log_name, reset_num_timesteps, progress_bar)

    def _excluded_save_params(self) -> list[str]:
        return [
            *super()._excluded_save_params(),
            "state_planner",
            "inverse_dynamics",
            "critic",
            "critic_target",
            "planner_lr_schedule",
            "inverse_dynamics_lr_schedule",
            "_plan_errors",
            "_planner_parameters",
            "_rollout_plan_mean",
        ]

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts = ["policy", "state_planner.optimizer", "inverse_dynamics.optimizer", "critic.optimizer"]
        if self.ent_coef_optimizer is not None:
            state_dicts.append("ent_coef_optimizer")
            return state_dicts, ["log_ent_coef"]
        return state_dicts, ["ent_coef_tensor"]
