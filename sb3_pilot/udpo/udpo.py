"""Universal Decoupled Policy Optimisation (UDPO), the pre-training stage of PILoT (paper section 3.1)."""

from typing import Any, ClassVar, TypeVar

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import NStepReplayBuffer, ReplayBuffer
from stable_baselines3.common.noise import ActionNoise
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.type_aliases import GymEnv, MaybeCallback, Schedule
from stable_baselines3.common.utils import (
    FloatSchedule,
    get_parameters_by_name,
    obs_as_tensor,
    update_learning_rate,
)
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer
from torch.nn import functional as F

from sb3_pilot.common.lean import LeanSACSteps, LossRecorder
from sb3_pilot.common.utils import check_number
from sb3_pilot.udpo.policies import (
    ENTROPY_TERMS,
    NO_SDE,
    ForwardDynamics,
    InverseDynamics,
    MlpPolicy,
    MultiInputPolicy,
    StatePlanner,
    UDPOPolicy,
    check_observation_space,
)

SelfUDPO = TypeVar("SelfUDPO", bound="UDPO")

#: What the planner's likelihood term fits (see ``UDPO``'s ``plan_target``)
PLAN_TARGETS = ("policy", "buffer")


class UDPO(LeanSACSteps, OffPolicyAlgorithm):
    """
    Universal Decoupled Policy Optimisation (UDPO), PILoT's pre-training algorithm
    (Planning Immediate Landmarks of Targets, Liu et al., ICLR 2023, section 3.1).

    The goal-conditioned policy is decoupled as ``pi(a|s,g) = E_{s' ~ h(s'|s,g)} [I(a|s,s')]``:
    a state planner ``h`` (``policy.state_planner``) and an inverse dynamics model ``I``
    (``policy.inverse_dynamics``). Twin Q critics and the entropy temperature are trained as in SAC, with the lean steps
    of :mod:`sb3_pilot.common.lean` that :class:`~sb3_pilot.sac.LeanSAC` uses too (one ensemble for the critics, fused
    Adam, HER batches gathered in one pass, losses read once per ``train()``).

    - ``I`` is fitted by maximum likelihood on buffer transitions ``(s, s', a)`` every ``inverse_dynamics_interval``
      gradient steps (``Delta``) and held fixed in between: the actor loss reaches only the planner.
    - ``h`` minimises the SAC actor loss through the frozen ``I`` plus ``planner_coef`` (``lambda``) times the negative
      log-likelihood ``-log h(s'_target | s, g)`` of a next state ``s'_target``, the paper's constraint
      ``max E_{(s, s') ~ pi} [h(s' | s, g)]`` on the transitions of the policy. ``lambda`` defaults to 1e-4, not the
      paper's 1e-2 (measured, ``zoo_runs/sources/lambda`` and ``zoo_runs/sources/fetchpush``, 3-16 seeds a task):
      the term pulls the plan towards the buffer's moves; at 1e-2 that pull kept UDPO from the detour SAC + HER
      learns in a walled maze, and the preset's 5e-3 slowed it on Point-Locomotion (90% success at 1.4x SAC + HER's
      steps). 1e-3 was faster than 1e-2 on FetchReach, the walled maze and Point-Locomotion, but left UDPO at chance on
      Fetch-Push, which it learns at 1e-4. 1e-4 is no slower than 1e-3 on FetchReach, Point-Locomotion, Reacher and
      Maze2D (steps to 90%: 1.00x / 1.07x / 0.88x / 0.94x, every interval holding 1; Reacher's area +0.07 [0.01,
      0.12]), on the walled maze (area 0.37 against 0.30, 16 seeds), and its state planner transfers (High-Dim-Action:
      90% on 3 of 3 seeds), if less well than 1e-3's (FetchReach's preset keeps 1e-3 for that).
      ``lambda = 0`` learns the source tasks but not a state planner: its plans are no next states (planner-mean
      error 35-62 against 0.6-0.8 at 1e-3 on FetchReach) and the planner transfers nothing (High-Dim-Action: 0.00
      success against 1.00). ``plan_target`` says which ``s'_target``:

      * ``"buffer"`` (default): the real next state of the sampled buffer transition (the implementation of the
        paper and of sb3-pilot 0.1). The buffer's transitions are those of all past behaviour policies and of
        HER-relabelled goals, not of ``pi``: a weak ``lambda`` leaves the plan where the actor loss puts it (beyond
        reach: planned steps 1.6x to 6x the real step on U-mazes at ``lambda = 1e-2``), a strong one pulls it to the
        average move of the buffer (0.2x at ``lambda = 1``), so ``lambda`` has to be tuned per task.
      * ``"policy"`` (opt-in): the transition of the policy's own action. A forward dynamics model ``T(s' | s, a)``
        (``policy.forward_dynamics``, fitted by maximum likelihood on every sampled minibatch of buffer transitions)
        predicts where the action ``a ~ I(. | s, s'_plan)`` taken for the sampled plan leads:
        ``s'_target = E[T(. | s, a)]``, held fixed in the gradient: an on-policy estimate of the paper's
        constraint. It pulls the plan towards the next state the policy reaches, but at ``lambda = 1e-2`` not all
        the way (measured: the planner's mean is still 1.9x-2.4x the real step on two 2D mazes, see
        ``zoo_runs/landmarks``). The immediate landmark is ``E[T(. | s, I(s, E[h]))]``, where the policy's
        deterministic action leads, which ``sb3_pilot.distill.distill_goal_planner`` distils by default for such a
        teacher (``labels="reached"``): on Maze2D (seed 0) its landmarks step 1.00x the real step and a point
        following them reaches the far goal for every k = 1..5, but 11/40 of them lie in walls (4-6/40 with
        ``"buffer"``) and UDPO runs 0.81x SAC's steps/s on FetchReach (0.98x with ``"buffer"``): not the default
        until it is measured on more seeds and tasks.
    - The entropy terms need ``log pi(a | s, g)``, intractable for the decoupled policy. ``entropy_term`` says how it
      is estimated (see :class:`UDPOPolicy`): ``"inverse_dynamics"`` (default) uses ``log I(a | s, s')`` at the sampled
      plan, as DePO does, on which the planner's spread has no hold; ``"linearised"`` linearises ``I``'s mean at the
      sampled plan, so that the planner's spread enters it and the temperature controls how widely the policy acts, as
      SAC's does. Measured (``zoo_runs/sources/lambda``): on the walled maze ``"linearised"`` reaches 90% success on
      13 of 16 seeds against 2-4 (area +0.20 [0.02, 0.33]), but on FetchReach, PointLocomotion and Reacher it reaches
      90% later than the default (1.2x, 1.4x, 1.3x its steps) and does not learn FetchPush either; its gradient step
      costs 1.5-1.7x. So the default stays DePO's; ``"linearised"`` is for tasks where a detour must be found.
    - The likelihood term pulls the plan's mean by ``(mu - s'_target) / sigma_h^2`` per state dimension, so dimensions
      the planner predicts almost exactly (on FetchPush the object, the fingers) outweigh the actor loss's gradient
      (17-270x at ``lambda = 1e-3``). ``planner_nll_beta`` (opt-in) weights each dimension's term by
      ``sigma_h^(2 beta)`` (beta-NLL). Measured at 0.5 (``zoo_runs/sources/lambda``): 90% success on the walled maze on
      11 of 16 seeds against 4 (a hint), FetchReach no slower with plans nearer the real next states, PointLocomotion
      undecided at 3 seeds; not the default.

    The planner state ``s`` is ``observation`` concatenated with ``achieved_goal`` for Dict goal observations, so the
    goal mapping ``phi`` is the achieved-goal slice of the state (``policy.goal_slice``); with a Box observation
    (``"MlpPolicy"``) the planner is goal-free (DePO's RL setting). Works with ``HerReplayBuffer``.

    Logged: ``train/critic_loss``, ``train/actor_loss``, ``train/planner_nll`` (of ``s'_target``),
    ``train/planner_loss``, ``train/inverse_dynamics_loss``, ``train/forward_dynamics_loss`` (``plan_target="policy"``),
    ``train/ent_coef`` (+ ``train/ent_coef_loss``) and ``rollout/plan_error``, the
    paper's "pred-real-mse": for each stored transition ``(s, s')``, the mean squared error per state dimension between
    the planner's mean ``E[h(. | s, g)]`` and ``s'`` (in the policy's input space, i.e. normalised under
    ``VecNormalize``).

    Differences from SAC that the design imposes: no gSDE (the action comes from the inverse dynamics), no n-step
    returns (``I`` and ``h`` must fit one-step transitions ``s -> s'``), no image entries in the planner state (``h``
    predicts the next state as a Gaussian vector).

    :param policy: The policy model to use (``"MultiInputPolicy"`` for Dict goal envs, ``"MlpPolicy"``, or a class)
    :param env: The environment to learn from (if registered in Gym, can be str)
    :param learning_rate: learning rate of the critics and the entropy coefficient (paper: Q learning rate);
        it can be a function of the current progress remaining (from 1 to 0)
    :param buffer_size: size of the replay buffer
    :param learning_starts: how many steps of the model to collect transitions for before learning starts
    :param batch_size: Minibatch size for each gradient update
    :param tau: the soft update coefficient ("Polyak update", between 0 and 1)
    :param gamma: the discount factor
    :param train_freq: Update the model every ``train_freq`` steps (or a tuple like ``(5, "step")``)
    :param gradient_steps: How many gradient steps to do after each rollout (-1: as many as env steps)
    :param action_noise: the action noise type (None by default)
    :param replay_buffer_class: Replay buffer class to use (for instance ``HerReplayBuffer``)
    :param replay_buffer_kwargs: Keyword arguments to pass to the replay buffer on creation
    :param optimize_memory_usage: Enable a memory efficient variant of the replay buffer
    :param n_steps: must be 1: n-step returns would make ``s'`` n steps ahead (accepted for SAC's signature)
    :param ent_coef: Entropy regularization coefficient, ``'auto'`` (or ``'auto_0.1'``) to learn it
    :param target_update_interval: update the target network every ``target_update_interval`` gradient steps
    :param target_entropy: target entropy when learning ``ent_coef`` (``'auto'``: ``-dim(action)``)
    :param use_sde: must be False: the action comes from the inverse dynamics (accepted for SAC's signature)
    :param planner_coef: ``lambda``, weight of the planner's negative log-likelihood of ``s'_target``
        (paper default 1e-2; 1e-4 here, measured: see above)
    :param planner_nll_beta: ``beta`` of the likelihood term as a beta-NLL (Seitzer et al., ICLR 2022): each state
        dimension's negative log-likelihood weighted by ``sigma_h^(2 beta)`` (held fixed). 0 (default) is the paper's
        term, whose pull on the plan's mean grows as ``1 / sigma_h^2``; 1 makes it a squared error on the mean
    :param plan_target: what the planner's likelihood term fits: ``"policy"``, the next state of the policy's own
        action predicted by a learned forward dynamics model (immediate landmarks), or ``"buffer"``, the real next
        state of buffer transitions (the paper's implementation)
    :param entropy_term: how the entropy terms estimate ``log pi(a | s, g)``: ``"inverse_dynamics"``
        (``log I(a | s, s')``, DePO's) or ``"linearised"`` (the decoupled policy with ``I`` linearised at the plan)
    :param inverse_dynamics_interval: ``Delta``, number of gradient steps between two refits of the inverse dynamics
        (paper default 1500, 200 for Fetch)
    :param inverse_dynamics_gradient_steps: supervised gradient steps of each refit of the inverse dynamics
    :param planner_learning_rate: learning rate of the state planner (paper: policy learning rate);
        None uses ``learning_rate``
    :param inverse_dynamics_learning_rate: learning rate of the inverse dynamics (paper: 1e-4);
        None uses ``learning_rate``
    :param stats_window_size: Window size for the rollout logging
    :param tensorboard_log: the log location for tensorboard (if None, no logging)
    :param policy_kwargs: additional arguments to be passed to the policy on creation
    :param verbose: Verbosity level: 0 no output, 1 info, 2 debug
    :param seed: Seed for the pseudo random generators
    :param device: Device (cpu, cuda, ...) on which the code should be run
    :param _init_setup_model: Whether or not to build the network at the creation of the instance
    """

    policy_aliases: ClassVar[dict[str, type[BasePolicy]]] = {
        "MlpPolicy": MlpPolicy,
        "MultiInputPolicy": MultiInputPolicy,
    }
    policy: UDPOPolicy
    state_planner: StatePlanner
    inverse_dynamics: InverseDynamics
    forward_dynamics: ForwardDynamics | None

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
        planner_nll_beta: float = 0.0,
        plan_target: str = "buffer",
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
        _init_setup_model: bool = True,
    ):
        if use_sde:
            raise ValueError(NO_SDE)
        check_number("planner_coef (lambda)", planner_coef, minimum=0)
        check_number("planner_nll_beta", planner_nll_beta, minimum=0, maximum=1)
        if plan_target not in PLAN_TARGETS:
            raise ValueError(f"plan_target must be one of {PLAN_TARGETS}, got {plan_target!r}.")
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
        self.planner_nll_beta = planner_nll_beta
        self.plan_target = plan_target
        self.entropy_term = entropy_term
        self.inverse_dynamics_interval = inverse_dynamics_interval
        self.inverse_dynamics_gradient_steps = inverse_dynamics_gradient_steps
        self.planner_learning_rate = planner_learning_rate
        self.inverse_dynamics_learning_rate = inverse_dynamics_learning_rate
        self._plan_errors: list[th.Tensor] = []
        self._rollout_plan_mean: th.Tensor | None = None

        if _init_setup_model:
            self._setup_model()

    def _setup_model(self) -> None:
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
            "forward_dynamics": self.plan_target == "policy",
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

    def _create_aliases(self) -> None:
        self.state_planner = self.policy.state_planner
        self.inverse_dynamics = self.policy.inverse_dynamics
        self.forward_dynamics = self.policy.forward_dynamics
        self.critic = self.policy.critic
        self.critic_target = self.policy.critic_target
        self._planner_parameters = list(self.state_planner.parameters())
        self._critic_parameters = list(self.critic.parameters())
        self._critic_target_parameters = list(self.critic_target.parameters())

    def train(self, gradient_steps: int, batch_size: int = 64) -> None:
        self.policy.set_training_mode(True)
        optimizers = [self.critic.optimizer]
        if self.ent_coef_optimizer is not None:
            optimizers.append(self.ent_coef_optimizer)
        self._update_learning_rate(optimizers)
        update_learning_rate(self.state_planner.optimizer, self.planner_lr_schedule(self._current_progress_remaining))
        if self.forward_dynamics is not None:
            update_learning_rate(
                self.forward_dynamics.optimizer, self.inverse_dynamics_lr_schedule(self._current_progress_remaining)
            )
        losses = LossRecorder()

        for gradient_step in range(gradient_steps):
            # I is refitted before the policy update that follows it (paper section 3.1, Algorithm 1)
            if (self._n_updates + gradient_step) % self.inverse_dynamics_interval == 0:
                self.train_inverse_dynamics(self.inverse_dynamics_gradient_steps, batch_size)
            if self.policy.freeze_state_planner:
                # A frozen h (a planner transferred from a source): pi(a | s, g) = I(a | s, h(s' | s, g)) reads neither
                # the critics nor the temperature, which exist to train h, so they are left as they are
                continue

            replay_data = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)  # type: ignore[union-attr]
            discounts = replay_data.discounts if replay_data.discounts is not None else self.gamma

            # a ~ I(. | s, s') at a reparameterised plan s' = h(eps; s, g) (eq. "repara"); I is held fixed: the planner
            # loss's backward reaches the planner's parameters only
            plan = self.policy.plan_and_act(replay_data.observations)
            log_prob = plan.log_prob.reshape(-1, 1)

            # Entropy coefficient loss (SAC), with the policy's log-probability as entropy_term estimates it
            ent_coef = self._entropy_coef_step(log_prob, losses)

            # Critic loss (SAC): 1/2 sum_i (Q_i(s, a, g) - y)^2,
            # y = r + gamma (1 - d) (min_i Q'_i(s', a', g) - alpha log pi(a' | s', g)), a' ~ I(. | s', s''), s'' ~ h(. | s', g)
            with th.no_grad():
                next_plan = self.policy.plan_and_act(replay_data.next_observations)
                next_q_values = self.critic_target.q_values(replay_data.next_observations, next_plan.actions).amin(dim=0)
                next_q_values = next_q_values - ent_coef * next_plan.log_prob.reshape(-1, 1)
                target_q_values = replay_data.rewards + (1 - replay_data.dones) * discounts * next_q_values

            self._critic_step(replay_data.observations, replay_data.actions, target_q_values, losses)

            # DePG actor loss (eq. "depg"): E[alpha log pi(a | s, g) - min_i Q_i(s, a, g)] through the frozen I and critics
            min_qf_pi = self.critic.q_values(replay_data.observations, plan.actions).amin(dim=0)
            actor_loss = (ent_coef * log_prob - min_qf_pi).mean()
            # Planner likelihood term, the paper's constraint max E_{(s,s') ~ pi}[h(s' | s, g)]: -log h(s'_target | s, g)
            real_next_state = self.state_planner.planner_state(replay_data.next_observations)
            if self.forward_dynamics is not None:
                # plan_target="policy": (s, s') ~ pi, s' ~ T(. | s, a) for the policy's own action a ~ I(. | s, s'_plan)
                losses.add(
                    "forward_dynamics_loss",
                    self.train_forward_dynamics(plan.state, real_next_state, replay_data.actions),
                )
                with th.no_grad():
                    target_next_state = self.forward_dynamics(plan.state, plan.actions.detach())
            else:
                # plan_target="buffer": the buffer's real transition s -> s' (the behaviour policies' transitions)
                target_next_state = real_next_state
            planner_nll = -plan.distribution.log_prob(target_next_state).mean()
            planner_fit = planner_nll
            if self.planner_nll_beta:
                # beta-NLL: each state dimension's term weighted by sigma_h^(2 beta), so that dimensions the planner
                # predicts almost exactly (sigma_h -> 0) do not swamp the DePG gradient with a 1 / sigma_h^2 pull
                planner_fit = plan.distribution.beta_nll(target_next_state, self.planner_nll_beta).mean()
            # Planner loss: the final planner gradient of section 3.1, DePG + lambda * likelihood term
            planner_loss = actor_loss + self.planner_coef * planner_fit
            losses.add("actor_loss", actor_loss)
            losses.add("planner_nll", planner_nll)
            losses.add("planner_loss", planner_loss)
            self.state_planner.optimizer.zero_grad()
            planner_loss.backward(inputs=self._planner_parameters)
            self.state_planner.optimizer.step()

            # Target critics: SAC's rule
            self._update_target_critics(gradient_step)

        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        losses.record(self.logger)

    def train_forward_dynamics(self, state: th.Tensor, next_state: th.Tensor, actions: th.Tensor) -> th.Tensor:
        """
        One maximum-likelihood step of the forward dynamics ``T(s' | s, a)`` on a minibatch of buffer transitions
        (``plan_target="policy"``). Only ``policy.forward_dynamics`` changes.

        :param state: planner states ``s``
        :param next_state: planner states ``s'`` reached from them
        :param actions: the buffer actions in ``[-1, 1]``
        :return: the negative log-likelihood before the step
        """
        assert self.forward_dynamics is not None
        loss = -self.forward_dynamics.log_prob(state.detach(), next_state, actions).mean()
        self.forward_dynamics.optimizer.zero_grad()
        loss.backward()
        self.forward_dynamics.optimizer.step()
        return loss.detach()

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
        self.logger.record("train/inverse_dynamics_loss", mean_loss)
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
        The planner's landmark: the next planner state ``s' ~ h(. | s, g)`` for an observation (or a batch).
        This is the plan, not where the policy's action for it leads: with ``plan_target="policy"`` the latter is
        ``policy.forward_dynamics(s, I(s, E[h]))``, what ``distill_goal_planner`` distils by default.

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
            "forward_dynamics",
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
        if self.forward_dynamics is not None:
            state_dicts.append("forward_dynamics.optimizer")
        if self.ent_coef_optimizer is not None:
            state_dicts.append("ent_coef_optimizer")
            return state_dicts, ["log_ent_coef"]
        return state_dicts, ["ent_coef_tensor"]
