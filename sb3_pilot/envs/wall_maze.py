"""
The walled maze (pure numpy): a square with a wall between its two lower halves, which an agent must go around through
a gap. ``Pilot/WallMaze2D-v0`` moves a point in it (a source, the teacher of the ``wall-maze-car`` challenge) and
``Pilot/WallMaze2DCar-v0`` a car with :class:`~sb3_pilot.envs.car.Maze2DCarEnv`'s dynamics (speed and turn rate, the
target); both have the same starts, goals and goal space (the xy of the square).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sb3_pilot.envs.car import Maze2DCarEnv
from sb3_pilot.envs.core import GoalReachingMixin, check_render_mode, goal_observation, goal_observation_space

#: The goal space of the walled-maze tasks (``goal_space_id``): the xy position in the square, whatever moves there
WALL_MAZE_GOAL_SPACE = "Pilot/wall-maze-xy"
WALL_MAZE_DISTANCE_THRESHOLD = 0.1
#: Starts and goals are drawn in ``[-WALL_MAZE_SAMPLE_BOUND, WALL_MAZE_SAMPLE_BOUND]^2``, off the wall and its sides
WALL_MAZE_SAMPLE_BOUND = 0.9


@dataclass(frozen=True)
class WallMaze:
    """
    The map: the square ``[-1, 1]^2`` with a wall along ``x = 0``, ``wall_half_width`` on each side, from ``y = -1`` up
    to ``y = gap_y``. A move that would cross the wall (or end in it) leaves the agent where it is, or, with ``slide``,
    keeps its part along the wall (``y``) if that one is free, else its part across it (``x``); moves end inside the
    square.

    :param gap_y: the wall covers ``y < gap_y``
    :param wall_half_width: half the wall's width
    :param slide: a blocked move slides along the wall instead of leaving the agent where it is
    """

    gap_y: float = 0.0
    wall_half_width: float = 0.05
    slide: bool = False

    def __post_init__(self) -> None:
        if not -1.0 < self.gap_y < 1.0:
            raise ValueError(f"gap_y must be in (-1, 1) (the wall covers y < gap_y), got {self.gap_y!r}")
        if not 0.0 <= self.wall_half_width < WALL_MAZE_SAMPLE_BOUND / 2:
            raise ValueError(f"wall_half_width must be in [0, {WALL_MAZE_SAMPLE_BOUND / 2}), got {self.wall_half_width!r}")

    def is_free(self, points: np.ndarray) -> np.ndarray:
        """
        :param points: xy of shape (..., 2)
        :return: boolean array of shape (...): the point lies in the square and not in the wall
        """
        points = np.asarray(points, dtype=np.float64)
        in_square = np.all(np.abs(points) <= 1.0, axis=-1)
        in_wall = (np.abs(points[..., 0]) <= self.wall_half_width) & (points[..., 1] < self.gap_y)
        return in_square & ~in_wall

    def blocked(self, start: np.ndarray, end: np.ndarray) -> bool:
        """Whether the straight move from ``start`` to ``end`` hits the wall."""
        if abs(end[0]) <= self.wall_half_width and end[1] < self.gap_y:
            return True
        if np.sign(start[0]) == np.sign(end[0]):
            return False
        crossing_y = start[1] + (end[1] - start[1]) * (0.0 - start[0]) / (end[0] - start[0])
        return bool(crossing_y < self.gap_y)

    def move(self, position: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """
        :param position: current xy (free)
        :param delta: the intended displacement
        :return: the new xy (free): ``position + delta`` clipped to the square, unless the wall blocks it (see above)
        """
        target = np.clip(position + delta, -1.0, 1.0)
        if not self.blocked(position, target):
            return target
        if self.slide:  # the move along the wall (y), else across it (x), else none
            for partial in (np.array([position[0], target[1]]), np.array([target[0], position[1]])):
                if not self.blocked(position, partial):
                    return partial
        return position

    def sample_free(self, rng: np.random.Generator) -> np.ndarray:
        """A position uniform in ``[-0.9, 0.9]^2`` off the wall: more than twice its half width from ``x = 0``, or above
        the gap."""
        while True:
            position = rng.uniform(-WALL_MAZE_SAMPLE_BOUND, WALL_MAZE_SAMPLE_BOUND, size=2)
            if abs(position[0]) > 2 * self.wall_half_width or position[1] > self.gap_y:
                return position

    def start_and_goal(self, rng: np.random.Generator, options: dict[str, Any] | None) -> tuple[np.ndarray, np.ndarray]:
        """
        :param rng: the random generator
        :param options: ``reset`` options: ``start`` and ``goal`` (xy) place them, else each is drawn by
            :meth:`sample_free` (the start first)
        :return: start and goal xy
        """
        options = options or {}
        start = np.array(options["start"], dtype=float) if "start" in options else self.sample_free(rng)
        goal = np.array(options["goal"], dtype=float) if "goal" in options else self.sample_free(rng)
        return start, goal


class WallMaze2DEnv(GoalReachingMixin, gym.Env):
    """
    ``Pilot/WallMaze2D-v0``: a point that moves kinematically in the walled maze (:class:`WallMaze`), by
    ``step_size * clip(action, -1, 1)`` a step. To go from one lower half to the other, it must go up around the wall
    through the gap. Starts and goals are uniform off the wall (:meth:`WallMaze.start_and_goal`;
    ``reset(options={"start": xy, "goal": xy})`` places them). Observation, achieved goal: the position (2); success
    within 0.1.

    :param step_size: largest displacement per axis and step
    :param gap_y: the wall covers ``y < gap_y``
    :param wall_half_width: half the wall's width
    :param slide: a blocked move slides along the wall (see :class:`WallMaze`)
    :param render_mode: unsupported (must be None)
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012
    goal_space_id = WALL_MAZE_GOAL_SPACE

    def __init__(
        self,
        step_size: float = 0.2,
        gap_y: float = 0.0,
        wall_half_width: float = 0.05,
        slide: bool = False,
        render_mode: str | None = None,
    ):
        check_render_mode(render_mode, ())
        if not 0 < step_size < 1:
            raise ValueError(f"step_size must be in (0, 1), got {step_size!r}")
        self.maze = WallMaze(gap_y, wall_half_width, slide)
        self.step_size = step_size
        self.distance_threshold = WALL_MAZE_DISTANCE_THRESHOLD
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = goal_observation_space(spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32), 2)
        self.position = np.zeros(2)
        self.goal = np.zeros(2)

    def _get_obs(self) -> dict[str, np.ndarray]:
        return goal_observation(self.position.astype(np.float32), self.position, self.goal)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.position, self.goal = self.maze.start_and_goal(self.np_random, options)
        obs = self._get_obs()
        return obs, self._goal_reward_info(obs)[1]

    def step(self, action: np.ndarray):
        self.position = self.maze.move(self.position, self.step_size * np.clip(action, -1.0, 1.0))
        obs = self._get_obs()
        reward, info = self._goal_reward_info(obs)
        return obs, reward, False, False, info


class WallMaze2DCarEnv(Maze2DCarEnv):
    """
    ``Pilot/WallMaze2DCar-v0``: :class:`~sb3_pilot.envs.car.Maze2DCarEnv`'s car (turn by ``max_turn * a[1]``, then
    move ``max_speed * a[0]`` along the heading) in the walled maze of ``Pilot/WallMaze2D-v0``, with its starts, goals
    and success distance; the initial heading is uniform. Observation: ``(x, y, cos theta, sin theta)`` (4); achieved
    goal: the position (2). A planner distilled on the point plans for it (one goal space).

    :param max_speed: largest move per step (the point moves up to 0.2 per axis)
    :param max_turn: largest turn per step, in radians
    :param gap_y: the wall covers ``y < gap_y``
    :param wall_half_width: half the wall's width
    :param slide: a blocked move slides along the wall (see :class:`WallMaze`)
    :param render_mode: unsupported (must be None)
    """

    goal_space_id = WALL_MAZE_GOAL_SPACE

    def __init__(
        self,
        max_speed: float = 0.2,
        max_turn: float = np.pi / 4,
        gap_y: float = 0.0,
        wall_half_width: float = 0.05,
        slide: bool = False,
        render_mode: str | None = None,
    ):
        if not 0 < max_speed < 1:
            raise ValueError(f"max_speed must be in (0, 1), got {max_speed!r}")
        super().__init__(max_speed=max_speed, max_turn=max_turn, render_mode=render_mode)
        self.maze = WallMaze(gap_y, wall_half_width, slide)
        self.distance_threshold = WALL_MAZE_DISTANCE_THRESHOLD

    def _start_and_goal(self, options: dict[str, Any] | None) -> tuple[np.ndarray, np.ndarray]:
        return self.maze.start_and_goal(self.np_random, options)

    def _move(self, position: np.ndarray, delta: np.ndarray) -> np.ndarray:
        return self.maze.move(position, delta)
