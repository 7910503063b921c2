"""Zero-shot landmark guidance of a pre-trained goal-conditioned controller (paper section 3.3)."""

from __future__ import annotations

import os
from typing import Any, NamedTuple, SupportsFloat

import gymnasium as gym
import numpy as np

from sb3_pilot.common.utils import check_number
from sb3_pilot.distill import GoalPlanner


class LandmarkGuidance(gym.Wrapper):
    """
    Zero-shot guidance (paper section 3.3): a pre-trained goal-conditioned controller (any SB3 model) sees the
    planner's immediate landmark as its ``desired_goal``, while the env still judges reward and success against the
    real goal (the wrapper passes them through untouched).

    The landmark is ``k = horizon`` chained planner steps ahead of the achieved goal; the real goal is shown instead
    once it is within reach: closer than ``switch_distance``, or (``switch_distance=None``) closer than the landmark.
    With ``snap``, every chained landmark is a goal the source agent really occupied (:meth:`GoalPlanner.snap`).
    ``info["landmark"]`` and ``info["real_desired_goal"]`` are added at each step, and the episode's landmarks and
    achieved goals are kept in :attr:`episode_landmarks` and :attr:`episode_achieved_goals`, for drawing.

    :param env: a goal env (Dict observation with ``achieved_goal`` and ``desired_goal``)
    :param planner: the distilled goal planner, or the path of its file; its goal size and source task are checked
        against ``env``. With a ``goal_map`` between the source task and the env's (:func:`~sb3_pilot.share_goal_space`),
        the planner plans in its coordinates and the landmarks are mapped into the env's
    :param horizon: number ``k`` of chained planner steps to the landmark
    :param switch_distance: distance to the real goal under which it replaces the landmark (None: the landmark's
        distance; 0: never)
    :param snap: snap the landmarks to the planner's support goals (positions the source really occupied). Off by
        default, unlike :meth:`GoalPlanner.plan`'s: it removes landmarks inside walls, but a controller that does not
        follow landmarks exactly may gain nothing from it (measurements: ``docs/results/landmarks.md``)
    """

    def __init__(
        self,
        env: gym.Env,
        planner: GoalPlanner | str | os.PathLike,
        horizon: int = 1,
        switch_distance: float | None = None,
        snap: bool = False,
    ):
        check_number("horizon", horizon, minimum=1, integer=True)
        if switch_distance is not None:
            check_number("switch_distance", switch_distance, minimum=0)
        super().__init__(env)
        self.planner, self.goal_map = GoalPlanner.for_env(planner, env)
        self.horizon = horizon
        self.switch_distance = switch_distance
        self.snap = snap
        if snap and not self.planner.has_support:
            raise ValueError("snap=True needs a goal planner with support goals: distil it again, or pass snap=False.")
        self.real_desired_goal: np.ndarray | None = None
        self._landmarks: list[np.ndarray] = []
        self._achieved_goals: list[np.ndarray] = []

    @property
    def episode_landmarks(self) -> np.ndarray:
        """Goals shown to the controller since the last reset, shape (steps + 1, goal_dim)."""
        return np.array(self._landmarks)

    @property
    def episode_achieved_goals(self) -> np.ndarray:
        """Achieved goals since the last reset, shape (steps + 1, goal_dim)."""
        return np.array(self._achieved_goals)

    def landmark(self, achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
        """The goal to show the controller at ``achieved_goal`` for the real goal ``desired_goal``."""
        if self.goal_map is None:
            landmark = self._planned(achieved_goal, desired_goal)
        else:  # the planner plans in its source task's coordinates
            landmark = self.goal_map.through(self._planned, achieved_goal, desired_goal)
        distance = np.linalg.norm(desired_goal - achieved_goal)
        reach = np.linalg.norm(landmark - achieved_goal) if self.switch_distance is None else self.switch_distance
        return np.array(desired_goal) if distance <= reach else landmark

    def _planned(self, achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
        """The ``horizon``-th chained landmark, in the planner's coordinates."""
        return self.planner.plan(achieved_goal, desired_goal, horizon=self.horizon, snap=self.snap)[-1]

    def _guide(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        self.real_desired_goal = np.array(observation["desired_goal"])
        landmark = self.landmark(observation["achieved_goal"], self.real_desired_goal).astype(
            observation["desired_goal"].dtype
        )
        self._landmarks.append(landmark)
        self._achieved_goals.append(np.array(observation["achieved_goal"]))
        return {**observation, "desired_goal": landmark}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        self._landmarks, self._achieved_goals = [], []
        return self._guide(observation), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        guided = self._guide(observation)
        info["landmark"], info["real_desired_goal"] = guided["desired_goal"], self.real_desired_goal
        return guided, reward, terminated, truncated, info


def landmark_leads(
    env: gym.Env, planner: GoalPlanner | str | os.PathLike, max_horizon: int = 10, episodes: int = 100, seed: int = 0
) -> np.ndarray:
    """
    How far ahead of the agent the ``k``-th chained landmark lies, ``k = 1 .. max_horizon``: the median over the
    task's own start and goal pairs (``episodes`` resets of ``env``, seeds ``10_000 * seed + i``) of
    ``||landmark_k - achieved_goal||``, in the env's goal units (through the planner's goal map, if any).

    :param env: the goal env to guide in
    :param planner: the goal planner, or its file
    :param max_horizon: the largest ``k``
    :param episodes: start and goal pairs
    :param seed: seed of the resets
    :return: the median lead at each ``k``, shape (max_horizon,)
    """
    check_number("max_horizon", max_horizon, minimum=1, integer=True)
    check_number("episodes", episodes, minimum=1, integer=True)
    goal_planner, goal_map = GoalPlanner.for_env(planner, env)
    starts, goals = _task_pairs(env, episodes, seed)

    def chained(achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
        return goal_planner.plan(achieved_goal, desired_goal, horizon=max_horizon, snap=False)

    landmarks = chained(starts, goals) if goal_map is None else goal_map.through(chained, starts, goals)
    return np.median(np.linalg.norm(landmarks - starts[:, None], axis=-1), axis=0)


def horizon_for_lead(
    env: gym.Env, planner: GoalPlanner | str | os.PathLike, lead: float, max_horizon: int = 10, episodes: int = 100
) -> int:
    """
    The guidance horizon ``k`` whose landmark lies closest to ``lead`` ahead of the agent (:func:`landmark_leads`): a
    controller trained on goals about ``lead`` away is shown landmarks about that far, whatever the planner's step.

    :param env: the goal env to guide in
    :param planner: the goal planner, or its file
    :param lead: the wanted distance of the landmark, in the env's goal units
    :param max_horizon: the largest ``k`` considered
    :param episodes: start and goal pairs the leads are measured on
    :return: ``k`` (ties to the smaller)
    """
    check_number("lead", lead, minimum=0, strict=True)
    return _closest_horizon(landmark_leads(env, planner, max_horizon=max_horizon, episodes=episodes), lead)


def _closest_horizon(leads: np.ndarray, lead: float) -> int:
    """The ``k`` (from 1) of the lead in ``leads`` closest to ``lead``, ties to the smaller."""
    return int(np.argmin(np.abs(leads - lead))) + 1


#: The success radius gymnasium-robotics' mazes (``PointMaze_*``, ``AntMaze_*``) hard-code (``maze_v4.MazeEnv``).
GYMNASIUM_ROBOTICS_MAZE_RADIUS = 0.45


def success_radius(env: gym.Env) -> float:
    """
    The distance to the goal within which a task counts it reached: its ``distance_threshold`` (the ``Pilot/`` tasks,
    gymnasium-robotics' Fetch), else :data:`GYMNASIUM_ROBOTICS_MAZE_RADIUS` for gymnasium-robotics' mazes.

    :param env: a goal env
    :raise ValueError: for a task that says neither (pass the radius yourself)
    """
    task = env.unwrapped
    radius = getattr(task, "distance_threshold", None)
    if radius is not None:
        return float(radius)
    if type(task).__module__.startswith("gymnasium_robotics.envs.maze"):
        return GYMNASIUM_ROBOTICS_MAZE_RADIUS
    raise ValueError(
        f"{type(task).__name__} says no success radius (no distance_threshold attribute): give it (--success-radius)."
    )


def _task_pairs(env: gym.Env, episodes: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The achieved and desired goals of ``episodes`` resets of ``env`` (seeds ``10_000 * seed + i``)."""
    pairs = [env.reset(seed=10_000 * seed + episode)[0] for episode in range(episodes)]
    starts = np.array([pair["achieved_goal"] for pair in pairs], dtype=np.float64)
    return starts, np.array([pair["desired_goal"] for pair in pairs], dtype=np.float64)


def goal_bias(
    env: gym.Env, planner: GoalPlanner | str | os.PathLike, horizon: int, episodes: int = 100, seed: int = 0
) -> float:
    """
    How far from a goal the planner's landmark for it lies once the agent is there: the median over the task's goals
    (``episodes`` resets) of ``||landmark_k(g, g) - g||``. A controller that follows the landmarks settles about there,
    and with the default switch rule (the real goal once it is closer than the landmark) it never sees the goal itself.

    :param env: the goal env to guide in
    :param planner: the goal planner, or its file
    :param horizon: the guidance horizon ``k``
    :param episodes: goals measured (resets of ``env``)
    :param seed: seed of the resets
    """
    check_number("horizon", horizon, minimum=1, integer=True)
    goal_planner, goal_map = GoalPlanner.for_env(planner, env)
    _, goals = _task_pairs(env, episodes, seed)

    def chained(achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
        return goal_planner.plan(achieved_goal, desired_goal, horizon=horizon, snap=False)[:, -1]

    landmarks = chained(goals, goals) if goal_map is None else goal_map.through(chained, goals, goals)
    return float(np.median(np.linalg.norm(landmarks - goals, axis=-1)))


class GuidanceSettings(NamedTuple):
    """
    :func:`choose_guidance`'s choice, and what it was chosen from.

    :param horizon: the guidance horizon ``k``
    :param switch_distance: :class:`LandmarkGuidance`'s ``switch_distance``
    :param leads: the median lead of the ``k``-th landmark, ``k = 1 .. max_horizon`` (:func:`landmark_leads`)
    :param goal_bias: :func:`goal_bias` at ``horizon``
    :param success_radius: the task's success radius
    """

    horizon: int
    switch_distance: float
    leads: np.ndarray
    goal_bias: float
    success_radius: float


def choose_guidance(
    env: gym.Env,
    planner: GoalPlanner | str | os.PathLike,
    lead: float,
    radius: float | None = None,
    max_horizon: int = 10,
    episodes: int = 100,
) -> GuidanceSettings:
    """
    The guidance settings of a planner on a task, from the planner and the task's success radius, measured on the
    task's own start and goal pairs (no episode is played): ``k`` whose landmark lies closest to ``lead`` ahead
    (:func:`horizon_for_lead`), and a switch to the real goal within the success radius plus the planner's
    :func:`goal_bias` at that ``k``, so that an agent settled on the landmark of a goal sees the goal.

    :param env: the goal env to guide in
    :param planner: the goal planner, or its file
    :param lead: the wanted distance of the landmark ahead, in the env's goal units (the controller's training goals')
    :param radius: the task's success radius (None: :func:`success_radius`)
    :param max_horizon: the largest ``k`` considered
    :param episodes: start and goal pairs measured
    """
    check_number("lead", lead, minimum=0, strict=True)
    radius = success_radius(env) if radius is None else radius
    check_number("radius", radius, minimum=0)
    leads = landmark_leads(env, planner, max_horizon=max_horizon, episodes=episodes)
    horizon = _closest_horizon(leads, lead)
    bias = goal_bias(env, planner, horizon, episodes=episodes)
    return GuidanceSettings(horizon, radius + bias, leads, bias, radius)
