"""The training env's side of MEGA: behaviour goals replace the env's goals, with rewards recomputed for them."""

from __future__ import annotations

from typing import Protocol

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

from sb3_pilot.common.utils import check_number

#: Info key keeping the env's own ``is_success`` (for its goal) when the behaviour goal's replaces it.
ENV_IS_SUCCESS = "env_is_success"


class BehaviourGoalSource(Protocol):
    """What chooses the behaviour goals of :class:`MegaGoalWrapper` (:class:`~sb3_pilot.baselines.MegaCallback`)."""

    def select_goals(self, observations: dict[str, np.ndarray]) -> np.ndarray | None:
        """
        :param observations: first observations of the episodes that start (a batch, as the env gives them)
        :return: their behaviour goals, shape (batch, goal_dim), or None to keep the env's goals
        """

    def record_episodes(self, reached: np.ndarray) -> None:
        """
        :param reached: for each episode that ended, whether it reached its behaviour goal at some step
        """


def check_goal_space(observation_space: spaces.Space) -> spaces.Box:
    """
    Refuse, with the reason, an observation space whose goals MEGA cannot fit a density to.

    :param observation_space: the env's observation space
    :return: the goal space (a 1-D float ``Box``; unbounded is fine: the density standardises the goals it sees)
    """
    if not isinstance(observation_space, spaces.Dict) or not {"achieved_goal", "desired_goal"} <= set(
        observation_space.spaces
    ):
        raise ValueError(
            "MEGA needs a goal env: a Dict observation with 'achieved_goal' and 'desired_goal' "
            f"(it picks behaviour goals among the achieved ones), got {observation_space}."
        )
    achieved, desired = observation_space["achieved_goal"], observation_space["desired_goal"]
    for name, space in (("achieved_goal", achieved), ("desired_goal", desired)):
        if not isinstance(space, spaces.Box) or len(space.shape) != 1 or not np.issubdtype(space.dtype, np.floating):
            raise ValueError(
                f"MEGA fits a kernel density to goal vectors: '{name}' must be a 1-D float Box, got {space} "
                "(images, discrete or integer goals have no such density here)."
            )
    if achieved.shape != desired.shape:
        raise ValueError(f"'achieved_goal' {achieved.shape} and 'desired_goal' {desired.shape} must have the same shape.")
    return desired


class MegaGoalWrapper(VecEnvWrapper):
    """
    Makes the training episodes of a goal env pursue behaviour goals (MEGA's, chosen by
    :class:`~sb3_pilot.baselines.MegaCallback`) instead of the env's goals.

    While a :class:`BehaviourGoalSource` is attached (the callback attaches itself for the time of ``learn``), each
    episode that starts gets a behaviour goal ``g_b``, and until it ends every observation's ``desired_goal``
    (the terminal observation's too) is ``g_b``, every reward is the env's ``compute_reward(achieved_goal, g_b, info)``
    and ``info["is_success"]`` says whether ``||achieved_goal - g_b|| <= success_distance`` (the env's own value moves
    to ``info["env_is_success"]``). So SB3's replay buffer stores ``g_b`` with rewards for ``g_b``, and
    ``HerReplayBuffer`` relabels those transitions like any other. Without a source (an evaluation env, or after
    ``learn``), episodes keep the env's goals and the wrapper changes nothing.

    Go-explore (mrl's ``go_eexplore``): once an episode has reached its behaviour goal, each of its steps takes a
    uniform random action with probability ``min(1, go_explore_rate x n)``, ``n`` the episode's steps so far within
    ``success_distance`` of ``g_b``: the agent walks to the frontier, then explores beyond it. The source sets the
    rate; the random actions of the last step are in ``explored`` / ``explored_actions`` (in ``[-1, 1]``, as SB3's
    replay buffer stores Box actions), from which :class:`~sb3_pilot.baselines.MegaCallback` makes the stored actions
    the executed ones.

    It works on raw goals: place it inside ``VecNormalize`` (the RL Zoo's ``vec_env_wrapper`` is), and outside any
    reward wrapper whose ``compute_reward`` should see the behaviour goal (``PilotBonusWrapper``: the bonus is then
    that of ``g_b``). The rewards come from ``env_method("compute_reward", ..., indices=[0])``, as in
    ``HerReplayBuffer``.

    :param venv: a vectorized goal env (Dict observation with 1-D float ``achieved_goal`` and ``desired_goal``)
    :param success_distance: distance under which a behaviour goal counts as reached; None reads the env's
        ``distance_threshold`` (gymnasium-robotics' and the ``Pilot/`` tasks')
    """

    def __init__(self, venv: VecEnv, success_distance: float | None = None):
        goal_space = check_goal_space(venv.observation_space)
        super().__init__(venv)
        if success_distance is None:
            try:
                success_distance = float(venv.get_attr("distance_threshold", indices=[0])[0])
            except AttributeError:
                raise ValueError(
                    "The env has no distance_threshold: pass success_distance, the distance under which a goal counts "
                    "as reached."
                ) from None
        check_number("success_distance", success_distance, minimum=0, strict=True)
        self.success_distance = success_distance
        self.source: BehaviourGoalSource | None = None
        self.behaviour_goals = np.zeros((self.num_envs, *goal_space.shape), dtype=goal_space.dtype)
        # which envs' current episodes pursue a behaviour goal, and which have reached it
        self.replaced = np.zeros(self.num_envs, dtype=bool)
        self.reached = np.zeros(self.num_envs, dtype=bool)
        # go-explore: the rate (0: off), each episode's steps at its behaviour goal, and the last step's random actions
        self.go_explore_rate = 0.0
        self.steps_at_goal = np.zeros(self.num_envs)
        self.explored = np.zeros(self.num_envs, dtype=bool)
        self.explored_actions = np.zeros((0, *self.action_space.shape), dtype=np.float32)

    def _start_episodes(self, observations: dict[str, np.ndarray], env_indices: np.ndarray) -> None:
        """
        Give the episodes that start in ``env_indices`` a behaviour goal (when the source has one), in place.

        :param observations: the batch of observations returned to the agent
        :param env_indices: the envs whose episodes start
        """
        self.replaced[env_indices] = False
        self.reached[env_indices] = False
        self.steps_at_goal[env_indices] = 0
        if self.source is None or len(env_indices) == 0:
            return
        goals = self.source.select_goals({key: value[env_indices] for key, value in observations.items()})
        if goals is None:
            return
        self.behaviour_goals[env_indices] = goals
        self.replaced[env_indices] = True
        observations["desired_goal"][env_indices] = goals

    def reset(self) -> VecEnvObs:
        observations = self.venv.reset()
        assert isinstance(observations, dict)
        self._start_episodes(observations, np.arange(self.num_envs))
        return observations

    def step_async(self, actions: np.ndarray) -> None:
        probability = np.minimum(1.0, self.go_explore_rate * self.steps_at_goal) if self.source is not None else 0.0
        self.explored = np.random.random(self.num_envs) < probability
        if self.explored.any():
            assert isinstance(self.action_space, spaces.Box)  # MegaCallback checks it when go-explore is on
            low, high = self.action_space.low, self.action_space.high
            self.explored_actions = np.random.uniform(-1.0, 1.0, (self.explored.sum(), *low.shape)).astype(np.float32)
            actions = actions.copy()
            actions[self.explored] = low + 0.5 * (self.explored_actions + 1.0) * (high - low)
        self.venv.step_async(actions)

    def step_wait(self) -> VecEnvStepReturn:
        observations, rewards, dones, infos = self.venv.step_wait()
        assert isinstance(observations, dict)
        rows = np.flatnonzero(self.replaced)
        if len(rows) > 0:
            # the transition's last observation: the terminal one where the env has reset
            last = [
                infos[i]["terminal_observation"] if dones[i] else {"achieved_goal": observations["achieved_goal"][i]}
                for i in rows
            ]
            achieved = np.stack([obs["achieved_goal"] for obs in last])
            goals = self.behaviour_goals[rows]
            rewards = rewards.copy()
            rewards[rows] = self.venv.env_method("compute_reward", achieved, goals, [infos[i] for i in rows], indices=[0])[0]
            success = np.linalg.norm(achieved - goals, axis=-1) <= self.success_distance
            self.reached[rows] |= success
            self.steps_at_goal[rows] += success
            for row, i in enumerate(rows):
                if "is_success" in infos[i]:
                    infos[i][ENV_IS_SUCCESS] = infos[i]["is_success"]
                infos[i]["is_success"] = bool(success[row])
                if dones[i]:
                    infos[i]["terminal_observation"]["desired_goal"] = goals[row].copy()
                else:
                    observations["desired_goal"][i] = goals[row]
            ended = rows[dones[rows]]
            if self.source is not None and len(ended) > 0:
                self.source.record_episodes(self.reached[ended].copy())
        self._start_episodes(observations, np.flatnonzero(dones))
        return observations, rewards, dones, infos
