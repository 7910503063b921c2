"""
``Pilot/Maze2DCar-v0``: a car-like agent in the U-maze of ``Pilot/Maze2D-v0`` (pure numpy), the target of the
``maze-car`` challenge. Its goals are Maze2D's (the xy of the maze), so a goal planner distilled on Maze2D plans for
it with no map; its actions (forward speed and turn rate) and state (heading) are not Maze2D's.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sb3_pilot.envs.core import GoalReachingMixin, check_render_mode, goal_observation, goal_observation_space
from sb3_pilot.envs.maze import GOAL_DISTRIBUTIONS, MAZE_DISTANCE_THRESHOLD, UMAZE_GOAL_SPACE, UMAZE_SCALING, UMazeMap


class Maze2DCarEnv(UMazeMap, GoalReachingMixin, gym.Env):
    """
    ``Pilot/Maze2DCar-v0``: a unicycle (car-like) agent in the U-maze of ``Pilot/Maze2D-v0``.

    State: position ``(x, y)`` and heading ``theta``. Action ``a`` in ``[-1, 1]^2``: the heading turns by
    ``max_turn * a[1]`` radians, then the position moves by ``max_speed * a[0]`` along the new heading (backwards for
    ``a[0] < 0``), sliding along walls as Maze2D's point does. Start and goal follow Maze2D's
    (:func:`~sb3_pilot.envs.maze.sample_umaze_start_goal`), the initial heading is uniform.
    Observation: ``(x, y, cos theta, sin theta)`` (4); achieved goal: the position (2); success within 1.0.

    :param goal_distribution: ``"far"`` or ``"uniform"``, see :func:`~sb3_pilot.envs.maze.sample_umaze_start_goal`
    :param max_speed: largest move per step, in world units (Maze2D's point moves up to 0.5 per axis)
    :param max_turn: largest turn per step, in radians
    :param render_mode: unsupported (must be None)
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012
    goal_space_id = UMAZE_GOAL_SPACE  # a Maze2D planner's landmarks are goals of this task too

    def __init__(
        self,
        goal_distribution: str = "uniform",
        max_speed: float = 0.5,
        max_turn: float = np.pi / 4,
        render_mode: str | None = None,
    ):
        check_render_mode(render_mode, ())
        if goal_distribution not in GOAL_DISTRIBUTIONS:
            raise ValueError(f"goal_distribution must be one of {GOAL_DISTRIBUTIONS}, got {goal_distribution!r}")
        if not 0 < max_speed < UMAZE_SCALING:
            raise ValueError(f"max_speed must be in (0, {UMAZE_SCALING}), got {max_speed!r}")
        if not 0 < max_turn <= np.pi:
            raise ValueError(f"max_turn must be in (0, pi] radians, got {max_turn!r}")
        self.goal_distribution = goal_distribution
        self.max_speed = max_speed
        self.max_turn = max_turn
        self.distance_threshold = MAZE_DISTANCE_THRESHOLD
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        obs_space = spaces.Box(-np.inf, np.inf, shape=(4,), dtype=np.float32)
        self.observation_space = goal_observation_space(obs_space, 2)
        self.position = np.zeros(2)
        self.heading = 0.0
        self.goal = np.zeros(2)

    def _get_obs(self) -> dict[str, np.ndarray]:
        state = np.array([*self.position, np.cos(self.heading), np.sin(self.heading)], dtype=np.float32)
        return goal_observation(state, self.position, self.goal)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.position, self.goal = self._start_and_goal(options)
        self.heading = float(self.np_random.uniform(-np.pi, np.pi))
        obs = self._get_obs()
        return obs, self._goal_reward_info(obs)[1]

    def step(self, action: np.ndarray):
        speed, turn = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        self.heading = float(np.angle(np.exp(1j * (self.heading + self.max_turn * turn))))  # wrapped to (-pi, pi]
        direction = np.array([np.cos(self.heading), np.sin(self.heading)])
        self.position = self._move(self.position, self.max_speed * speed * direction)
        obs = self._get_obs()
        reward, info = self._goal_reward_info(obs)
        return obs, reward, False, False, info
