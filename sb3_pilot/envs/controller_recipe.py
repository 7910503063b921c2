"""
The open-ground Ant controller's recipe as a wrapper, for goal envs of other packages: gymnasium-robotics'
``AntMaze_Open-v5`` (the ``pointmaze-to-antmaze`` challenge's controller), or any goal env of a MuJoCo Ant.

The recipe is the one ``Pilot/AntLocomotion-v0`` takes as task options (``hyperparams/cpu/ant_controller_upright.yml``):
goals a short walk from the Ant that move on once held, a dense reward of progress, staying upright and holding the
goal, episodes that end when it flips. Its inputs (the goal seen from the Ant, in its heading frame) are those of
:class:`~sb3_pilot.common.torch_layers.GoalRelativeExtractor`, whose ``position_dim``, ``quaternion_index`` and
``velocity_index`` fit gymnasium-robotics' observation layout (0, 1, 13: it holds the Ant's joint state without its
xy).
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from sb3_pilot.checks import check_number
from sb3_pilot.envs.locomotion import ant_up_z


class AntControllerRecipe(gym.Wrapper):
    """
    The open-ground controller's training task on a goal env of a MuJoCo Ant (its ``data`` on the unwrapped env, or on
    its ``ant_env`` as in gymnasium-robotics' ``AntMaze``): the env's own goal is replaced by one drawn at a distance
    uniform in ``goal_range`` from the Ant, in a uniform direction (in a maze, in free space at least ``wall_margin``
    from a wall); once reached (within ``distance_threshold``) and held for ``goal_hold_steps`` more steps, a new one
    is drawn around the Ant. The reward is dense: the progress towards the goal in units per second, plus
    ``upright_reward`` while the Ant is not flipped, plus ``goal_reward`` while the goal is reached, minus
    ``ctrl_cost_weight * ||a||^2``; ``compute_reward`` is the sparse -1/0 reward of the goals. The Ant counts as
    flipped once the z component of its torso's up axis is below ``flip_up_z``, which ends the episode with
    ``terminate_when_flipped``. ``info`` gets ``is_success``, ``flipped`` and ``goals_reached``.

    The defaults are ``hyperparams/cpu/ant_controller_upright.yml``'s options of ``Pilot/AntLocomotion-v0``.

    :param env: a goal env of a MuJoCo Ant (Dict observation with ``achieved_goal`` the Ant's xy)
    :param goal_range: ``(low, high)`` distance of a new goal from the Ant
    :param goal_hold_steps: steps a reached goal stays before a new one is drawn
    :param distance_threshold: success radius
    :param upright_reward: dense reward per step while the Ant is not flipped
    :param goal_reward: dense reward per step while the goal is reached
    :param ctrl_cost_weight: weight of the squared action in the dense reward
    :param flip_up_z: the Ant counts as flipped below this up-axis z (0.5: tilted more than 60 degrees)
    :param terminate_when_flipped: end the episode once the Ant is flipped
    :param wall_margin: in a gymnasium-robotics maze, the least distance (per axis) from a new goal to a wall cell
    """

    def __init__(
        self,
        env: gym.Env,
        goal_range: tuple[float, float] = (0.5, 3.0),
        goal_hold_steps: int = 25,
        distance_threshold: float = 0.5,
        upright_reward: float = 1.0,
        goal_reward: float = 1.0,
        ctrl_cost_weight: float = 0.25,
        flip_up_z: float = 0.5,
        terminate_when_flipped: bool = True,
        wall_margin: float = 1.0,
    ):
        super().__init__(env)
        low, high = (float(bound) for bound in goal_range)
        if not 0 <= low <= high:
            raise ValueError(f"goal_range must be (low, high) with 0 <= low <= high, got {goal_range!r}")
        check_number("goal_hold_steps", goal_hold_steps, minimum=0, integer=True)
        check_number("distance_threshold", distance_threshold, minimum=0, strict=True)
        check_number("wall_margin", wall_margin, minimum=0)
        check_number("flip_up_z", flip_up_z, minimum=-1.0, maximum=1.0)
        unwrapped = env.unwrapped
        self.ant = getattr(unwrapped, "ant_env", unwrapped)
        if not hasattr(self.ant, "data") or not hasattr(self.ant, "dt"):
            raise ValueError(
                f"AntControllerRecipe needs a MuJoCo Ant (its data and dt on the unwrapped env or its ant_env), got "
                f"{type(unwrapped).__name__}."
            )
        self.maze = getattr(unwrapped, "maze", None)
        self.goal_range = (low, high)
        self.goal_hold_steps = goal_hold_steps
        self.distance_threshold = float(distance_threshold)
        self.upright_reward = upright_reward
        self.goal_reward = goal_reward
        self.ctrl_cost_weight = ctrl_cost_weight
        self.flip_up_z = float(flip_up_z)
        self.terminate_when_flipped = terminate_when_flipped
        self.wall_margin = float(wall_margin)
        self.goal = np.zeros(2)
        self.goals_reached = 0
        self._steps_at_goal = 0

    def _free(self, xy: np.ndarray) -> bool:
        """Whether ``xy`` and the points ``wall_margin`` around it (per axis) lie in free cells of the maze."""
        if self.maze is None:
            return True
        for dx in (-self.wall_margin, 0.0, self.wall_margin):
            for dy in (-self.wall_margin, 0.0, self.wall_margin):
                row, col = self.maze.cell_xy_to_rowcol(xy + np.array([dx, dy]))
                if not (0 <= row < self.maze.map_length and 0 <= col < self.maze.map_width):
                    return False
                if self.maze.maze_map[row][col] == 1:
                    return False
        return True

    def _sample_goal(self, position: np.ndarray) -> np.ndarray:
        """A goal ``goal_range`` from ``position`` in a uniform direction, in free space (up to 100 draws)."""
        rng = self.env.unwrapped.np_random
        for _ in range(100):
            distance, angle = rng.uniform(*self.goal_range), rng.uniform(-np.pi, np.pi)
            goal = np.asarray(position, dtype=np.float64) + distance * np.array([np.cos(angle), np.sin(angle)])
            if self._free(goal):
                return goal
        return np.asarray(position, dtype=np.float64).copy()  # walled in: the goal is to stay

    def _observation(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        dtype = observation["desired_goal"].dtype
        return {**observation, "desired_goal": self.goal.astype(dtype)}

    def _distance(self, achieved_goal: np.ndarray) -> float:
        return float(np.linalg.norm(np.asarray(achieved_goal, dtype=np.float64) - self.goal))

    @property
    def flipped(self) -> bool:
        """Whether the z component of the torso's up axis is below ``flip_up_z``."""
        return ant_up_z(self.ant.data.qpos) < self.flip_up_z

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """The sparse reward of the goals: 0 within ``distance_threshold``, else -1 (vectorised)."""
        diff = np.asarray(achieved_goal, dtype=np.float64) - np.asarray(desired_goal, dtype=np.float64)
        return (np.linalg.norm(diff, axis=-1) <= self.distance_threshold).astype(np.float32) - 1.0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        self.goals_reached, self._steps_at_goal = 0, 0
        self.goal = self._sample_goal(observation["achieved_goal"])
        info = {**info, "is_success": self._distance(observation["achieved_goal"]) <= self.distance_threshold}
        return self._observation(observation), info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        previous_distance = self._distance(self.ant.data.qpos[:2])
        observation, _, terminated, truncated, info = self.env.step(action)
        distance = self._distance(self.ant.data.qpos[:2])
        success, flipped = self._distance(observation["achieved_goal"]) <= self.distance_threshold, self.flipped
        control_cost = self.ctrl_cost_weight * float(np.sum(np.square(action)))
        reward = (
            (previous_distance - distance) / self.ant.dt
            + self.upright_reward * float(not flipped)
            + self.goal_reward * float(success)
            - control_cost
        )
        if success:
            self._steps_at_goal += 1
            if self._steps_at_goal > self.goal_hold_steps:  # a new goal, seen from this observation on
                self.goals_reached += 1
                self._steps_at_goal = 0
                self.goal = self._sample_goal(observation["achieved_goal"])
        info = {**info, "is_success": bool(success), "flipped": flipped, "goals_reached": self.goals_reached}
        terminated = bool(terminated or (self.terminate_when_flipped and flipped))
        return self._observation(observation), reward, terminated, truncated, info
