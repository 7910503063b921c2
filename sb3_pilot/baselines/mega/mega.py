"""MEGA's choice of behaviour goals (mrl's ``DensityAchievedGoalCuriosity`` with its Q cut-off), as an SB3 callback."""

from __future__ import annotations

from collections import deque

import numpy as np
import torch as th
from gymnasium import spaces
from stable_baselines3.common.buffers import DictReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnvWrapper, VecFrameStack, VecNormalize, VecTransposeImage, unwrap_vec_wrapper

from sb3_pilot.baselines.mega.density import KernelDensity
from sb3_pilot.baselines.mega.goal_wrapper import MegaGoalWrapper
from sb3_pilot.common.utils import check_number


class MegaCallback(BaseCallback):
    """
    MEGA's behaviour goals for SB3's off-policy goal agents (SAC, TD3, DDPG, UDPO; with ``HerReplayBuffer``): at the
    start of each training episode, pick among ``n_candidates`` achieved goals ``g`` drawn from the replay buffer the
    one of lowest density ``p(g)`` (a :class:`KernelDensity` fitted on ``density_samples`` of the buffer's achieved
    goals) among those the agent values at least ``Q(s_0, g, pi(s_0, g)) >= cutoff`` (deemed reachable); if none
    passes, the one of highest value. The training env must be wrapped in :class:`MegaGoalWrapper`, which pursues the
    goals; evaluation envs keep the env's goals.

    The cut-off adapts as in mrl: every ``cutoff_window`` episodes, if the share that reached its behaviour goal is
    at least ``success_bounds[1]`` it drops by 1 (towards harder goals), never below the lowest value seen (and never
    below ``-(1 - gamma^(0.8 T)) / (1 - gamma)`` with ``T = max_episode_steps``); at most ``success_bounds[0]`` it
    rises by 1, never above ``initial_cutoff``. Defaults are mrl's MEGA settings.

    Go-explore as in mrl's MEGA runs (its ``go_eexplore``, on in them): once a training episode has reached its
    behaviour goal, each further step acts uniformly at random with probability ``go_explore`` times the episode's
    steps within reach of the goal so far (capped at 1); the replay buffer stores the actions taken. mrl adds this to
    an epsilon-random rate of 0.1 that every one of its agents has (HER too); SAC explores by its entropy, so only
    the go-explore part is added here. ``go_explore=0`` turns it off.

    The value is the minimum over the critic's Q-networks (SAC's target) at the deterministic action. Nothing of
    this callback is saved with the model: a model trained with it loads and runs like any other.

    :param n_candidates: achieved goals drawn from the buffer per episode (mrl: 100)
    :param bandwidth: the density's kernel width, in standard deviations of the goals (mrl: 0.1)
    :param density_samples: achieved goals the density is fitted on, drawn anew at each choice (mrl: 10000)
    :param initial_cutoff: the starting and largest cut-off on ``Q`` (mrl: -3)
    :param cutoff_window: episodes between cut-off updates (mrl: 10)
    :param success_bounds: shares of reached behaviour goals under / over which the cut-off rises / drops
        (mrl: 0.3, 0.7)
    :param max_episode_steps: episode length ``T`` of the lowest cut-off; None reads the env's ``TimeLimit``
    :param go_explore: random-action probability added per step spent at the behaviour goal (mrl: 0.1; 0: off);
        needs a bounded ``Box`` action space
    :param verbose: verbosity level
    """

    def __init__(
        self,
        n_candidates: int = 100,
        bandwidth: float = 0.1,
        density_samples: int = 10_000,
        initial_cutoff: float = -3.0,
        cutoff_window: int = 10,
        success_bounds: tuple[float, float] = (0.3, 0.7),
        max_episode_steps: int | None = None,
        go_explore: float = 0.1,
        verbose: int = 0,
    ):
        super().__init__(verbose)
        check_number("n_candidates", n_candidates, minimum=1, integer=True)
        check_number("density_samples", density_samples, minimum=1, integer=True)
        check_number("initial_cutoff", initial_cutoff)
        check_number("cutoff_window", cutoff_window, minimum=1, integer=True)
        if len(success_bounds) != 2 or not 0 <= success_bounds[0] < success_bounds[1] <= 1:
            raise ValueError(f"success_bounds must be (low, high) with 0 <= low < high <= 1, got {success_bounds!r}.")
        if max_episode_steps is not None:
            check_number("max_episode_steps", max_episode_steps, minimum=1, integer=True)
        check_number("go_explore", go_explore, minimum=0)
        self.n_candidates = n_candidates
        self.density = KernelDensity(bandwidth)
        self.density_samples = density_samples
        self.initial_cutoff = initial_cutoff
        self.success_bounds = success_bounds
        self.max_episode_steps = max_episode_steps
        self.go_explore = go_explore
        self.successes: deque[bool] = deque(maxlen=cutoff_window)
        self.goal_wrapper: MegaGoalWrapper | None = None
        # the observation-changing wrappers above MegaGoalWrapper, outermost first: what the policy sees of its goals
        self.outer_wrappers: list[VecNormalize | VecTransposeImage] = []
        self.lowest_cutoff = self.min_cutoff = self.cutoff = initial_cutoff

    def _init_callback(self) -> None:
        self.goal_wrapper = unwrap_vec_wrapper(self.training_env, MegaGoalWrapper)
        if self.goal_wrapper is None:
            raise ValueError(
                "MegaCallback needs the training env wrapped in sb3_pilot.baselines.MegaGoalWrapper "
                "(RL Zoo: vec_env_wrapper: sb3_pilot.baselines.MegaGoalWrapper)."
            )
        if unwrap_vec_wrapper(self.goal_wrapper, VecNormalize) is not None:
            raise ValueError("MegaGoalWrapper works on raw goals: wrap it in VecNormalize, not the other way round.")
        self.outer_wrappers = []
        env = self.training_env
        while env is not self.goal_wrapper:
            assert isinstance(env, VecEnvWrapper)
            if isinstance(env, VecFrameStack):
                raise ValueError("MegaCallback cannot value goals under VecFrameStack: the stacked history is unknown.")
            if isinstance(env, (VecNormalize, VecTransposeImage)):
                self.outer_wrappers.append(env)
            env = env.venv
        buffer = getattr(self.model, "replay_buffer", None)
        if not isinstance(buffer, DictReplayBuffer) or "achieved_goal" not in buffer.next_observations:
            raise TypeError(
                "MegaCallback draws goals from a Dict replay buffer with achieved goals (HerReplayBuffer), "
                f"got {type(buffer).__name__}."
            )
        if not isinstance(getattr(self.model.policy, "critic", None), th.nn.Module):
            raise TypeError(
                "MegaCallback reads the value Q(s, g, pi(s, g)) from the policy's critic (SAC, TD3, DDPG, UDPO); "
                f"{type(self.model.policy).__name__} has none."
            )
        space = self.goal_wrapper.action_space
        if self.go_explore > 0 and not (isinstance(space, spaces.Box) and np.all(np.isfinite([space.low, space.high]))):
            raise ValueError(
                f"MEGA's go-explore draws uniform random actions: it needs a bounded Box action space, got {space} "
                "(pass go_explore=0 to turn it off)."
            )
        horizon = self.max_episode_steps or self._env_horizon()
        discount = min(self.model.gamma, 0.99)  # type: ignore[attr-defined]
        self.lowest_cutoff = -(1 - discount ** (0.8 * horizon)) / (1 - discount)
        self.min_cutoff = self.cutoff = max(self.initial_cutoff, self.lowest_cutoff)
        self.successes.clear()

    def _env_horizon(self) -> int:
        """The episode length of the training env's ``TimeLimit``."""
        spec = self.training_env.get_attr("spec", indices=[0])[0]
        if spec is None or spec.max_episode_steps is None:
            raise ValueError("The env has no TimeLimit: pass max_episode_steps (T of MEGA's lowest cut-off).")
        return int(spec.max_episode_steps)

    def _on_training_start(self) -> None:
        assert self.goal_wrapper is not None
        self.goal_wrapper.source = self
        self.goal_wrapper.go_explore_rate = self.go_explore

    def _on_training_end(self) -> None:
        assert self.goal_wrapper is not None
        self.goal_wrapper.source = None
        self.goal_wrapper.go_explore_rate = 0.0

    def _on_step(self) -> bool:
        # called between the env step and the replay buffer's add (SB3's off-policy collect_rollouts): the stored
        # actions become the go-explore actions the env executed
        assert self.goal_wrapper is not None
        explored = self.goal_wrapper.explored
        if explored.any():
            self.locals["buffer_actions"][explored] = self.goal_wrapper.explored_actions
        self.logger.record_mean("mega/go_explore_share", float(explored.mean()))
        return True

    def _buffer_achieved_goals(self) -> np.ndarray:
        """The achieved goals stored in the replay buffer (those reached by its transitions), shape (n, goal_dim)."""
        buffer = self.model.replay_buffer  # type: ignore[attr-defined]
        stored = buffer.buffer_size if buffer.full else buffer.pos
        achieved = buffer.next_observations["achieved_goal"][:stored]
        return achieved.reshape(-1, achieved.shape[-1])

    def values(self, observations: dict[str, np.ndarray]) -> np.ndarray:
        """
        :param observations: raw goal observations (a batch, as :class:`MegaGoalWrapper` sees them), ``desired_goal``
            holding the goals to value; ``VecNormalize`` and ``VecTransposeImage`` above the wrapper are applied
        :return: ``min_j Q_j(s, g, pi(s, g))`` at the policy's deterministic action, shape (batch,)
        """
        for wrapper in reversed(self.outer_wrappers):  # as the training env's wrappers give them to the policy
            if isinstance(wrapper, VecNormalize):
                observations = wrapper.normalize_obs(observations)  # type: ignore[assignment]
            else:
                observations = wrapper.transpose_observations(observations)  # type: ignore[assignment]
        policy = self.model.policy
        obs_tensor, _ = policy.obs_to_tensor(observations)
        with th.no_grad():
            actions = policy._predict(obs_tensor, deterministic=True)  # type: ignore[arg-type]
            q_values = th.cat(policy.critic(obs_tensor, actions), dim=1)  # type: ignore[operator]
        return q_values.min(dim=1).values.cpu().numpy()

    def _update_cutoff(self, values: np.ndarray) -> None:
        """mrl's rule: move the cut-off by one after ``cutoff_window`` episodes of high or low success."""
        if len(self.successes) < self.successes.maxlen:  # type: ignore[operator]
            return
        self.min_cutoff = max(self.lowest_cutoff, min(float(values.min()), self.min_cutoff))
        success = float(np.mean(self.successes))
        if success >= self.success_bounds[1]:
            self.cutoff = max(self.min_cutoff, self.cutoff - 1.0)
            self.successes.clear()
        elif success <= self.success_bounds[0]:
            self.cutoff = max(min(self.initial_cutoff, self.cutoff + 1.0), self.lowest_cutoff)
            self.successes.clear()

    def choose(self, candidates: np.ndarray, values: np.ndarray) -> np.ndarray:
        """
        :param candidates: achieved goals, shape (batch, n_candidates, goal_dim)
        :param values: their values ``Q(s_0, g, pi(s_0, g))``, shape (batch, n_candidates)
        :return: per row, the candidate of lowest density among those valued at least ``cutoff``, or of highest value
            if none is; shape (batch, goal_dim)
        """
        batch, n_candidates, goal_dim = candidates.shape
        log_density = self.density.log_density(candidates.reshape(-1, goal_dim)).reshape(batch, n_candidates)
        reachable = values >= self.cutoff
        chosen = np.where(
            reachable.any(axis=1),
            np.argmin(np.where(reachable, log_density, np.inf), axis=1),
            np.argmax(values, axis=1),
        )
        return candidates[np.arange(batch), chosen]

    def select_goals(self, observations: dict[str, np.ndarray]) -> np.ndarray | None:
        """
        MEGA's behaviour goals for the episodes that start (``BehaviourGoalSource.select_goals``).

        :param observations: the episodes' first observations (raw), a batch
        :return: their behaviour goals, or None while the buffer holds no achieved goal
        """
        achieved = self._buffer_achieved_goals()
        if len(achieved) == 0:
            return None
        self.density.fit(achieved[np.random.randint(len(achieved), size=self.density_samples)])
        batch = len(observations["desired_goal"])
        candidates = achieved[np.random.randint(len(achieved), size=(batch, self.n_candidates))]
        # each start observation paired with each of its candidates as goal
        repeated = {key: np.repeat(value, self.n_candidates, axis=0) for key, value in observations.items()}
        repeated["desired_goal"] = candidates.reshape(batch * self.n_candidates, -1)
        values = self.values(repeated).reshape(batch, self.n_candidates)
        self._update_cutoff(values)
        goals = self.choose(candidates, values)
        self.logger.record("mega/cutoff", self.cutoff)
        return goals

    def record_episodes(self, reached: np.ndarray) -> None:
        """
        :param reached: whether each episode that ended reached its behaviour goal
        """
        self.successes.extend(bool(flag) for flag in reached)
        self.logger.record_mean("mega/behaviour_goal_reached", float(np.mean(reached)))
