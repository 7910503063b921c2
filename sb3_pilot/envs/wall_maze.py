"""
The walled maze (pure numpy): a square with a wall between its two lower halves, which an agent must go around through
a gap. ``Pilot/WallMaze2D-v0`` moves a point in it (a source, the teacher of the ``wall-maze-car`` challenge) and
``Pilot/WallMaze2DCar-v0`` a car with :class:`~sb3_pilot.envs.car.Maze2DCarEnv`'s dynamics (speed and turn rate, the
target); both have the same starts, goals and goal space (the xy of the square). Their options ``wall=False`` (the
open square: the same task without the wall, e.g. for an open-ground controller) and ``across=True`` (every start and
goal on opposite sides of the wall) change the map (:class:`WallMaze`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from sb3_pilot.envs.car import Maze2DCarEnv
from sb3_pilot.envs.core import goal_observation_space
from sb3_pilot.envs.maze import Maze2DEnv

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
    :param wall: False: no wall (the open square; starts and goals as with the wall, see :meth:`start_and_goal`)
    :param across: draw every start and goal below the gap on opposite sides of the wall (see :meth:`start_and_goal`)
    """

    gap_y: float = 0.0
    wall_half_width: float = 0.05
    slide: bool = False
    wall: bool = True
    across: bool = False

    def __post_init__(self) -> None:
        if not -1.0 < self.gap_y < 1.0:
            raise ValueError(f"gap_y must be in (-1, 1) (the wall covers y < gap_y), got {self.gap_y!r}")
        if not 0.0 <= self.wall_half_width < WALL_MAZE_SAMPLE_BOUND / 2:
            raise ValueError(f"wall_half_width must be in [0, {WALL_MAZE_SAMPLE_BOUND / 2}), got {self.wall_half_width!r}")
        if self.across and self.gap_y <= -WALL_MAZE_SAMPLE_BOUND:
            raise ValueError(
                f"across=True draws starts and goals below the gap, in y >= {-WALL_MAZE_SAMPLE_BOUND}: gap_y must be above "
                f"that, got {self.gap_y!r}"
            )

    def is_free(self, points: np.ndarray) -> np.ndarray:
        """
        :param points: xy of shape (..., 2)
        :return: boolean array of shape (...): the point lies in the square and not in the wall
        """
        points = np.asarray(points, dtype=np.float64)
        in_square = np.all(np.abs(points) <= 1.0, axis=-1)
        if not self.wall:
            return in_square
        in_wall = (np.abs(points[..., 0]) <= self.wall_half_width) & (points[..., 1] < self.gap_y)
        return in_square & ~in_wall

    def depth(self, points: np.ndarray) -> np.ndarray:
        """
        :param points: xy of shape (..., 2)
        :return: each point's distance to the free space, shape (...): 0 there and on a wall's face, else how deep
            the point lies in the wall or how far outside the square
        """
        points = np.asarray(points, dtype=np.float64)
        width, gap = self.wall_half_width, self.gap_y
        # the closure of the free space: the square, or its parts left of, right of and above the wall
        boxes = [((-1.0, -1.0), (-width, 1.0)), ((width, -1.0), (1.0, 1.0)), ((-1.0, gap), (1.0, 1.0))]
        if not self.wall:
            boxes = [((-1.0, -1.0), (1.0, 1.0))]
        distances = [
            np.linalg.norm(np.maximum(np.maximum(np.subtract(low, points), np.subtract(points, high)), 0.0), axis=-1)
            for low, high in boxes
        ]
        return np.min(distances, axis=0)

    def blocked(self, start: np.ndarray, end: np.ndarray) -> bool:
        """Whether the straight move from ``start`` to ``end`` hits the wall."""
        if not self.wall:
            return False
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

    def off_wall(self, points: np.ndarray) -> np.ndarray:
        """
        :param points: xy of shape (..., 2)
        :return: boolean array of shape (...): the point is where starts and goals may lie, more than twice the wall's
            half width from ``x = 0`` or above the gap (anywhere without the wall)
        """
        points = np.asarray(points, dtype=np.float64)
        if not self.wall:
            return np.ones(points.shape[:-1], dtype=bool)
        return (np.abs(points[..., 0]) > 2 * self.wall_half_width) | (points[..., 1] > self.gap_y)

    def sample_free(self, rng: np.random.Generator) -> np.ndarray:
        """A position uniform in ``[-0.9, 0.9]^2`` and :meth:`off_wall`."""
        while True:
            position = rng.uniform(-WALL_MAZE_SAMPLE_BOUND, WALL_MAZE_SAMPLE_BOUND, size=2)
            if self.off_wall(position):
                return position

    def sample_below_gap(self, rng: np.random.Generator, side: float) -> np.ndarray:
        """
        :param rng: the random generator
        :param side: -1 (left of the wall) or 1 (right of it)
        :return: a position uniform below the gap on that side, more than twice the wall's half width from
            ``x = 0``, within ``[-0.9, 0.9]^2``
        """
        x = side * rng.uniform(2 * self.wall_half_width, WALL_MAZE_SAMPLE_BOUND)
        return np.array([x, rng.uniform(-WALL_MAZE_SAMPLE_BOUND, min(self.gap_y, WALL_MAZE_SAMPLE_BOUND))])

    def start_and_goal(self, rng: np.random.Generator, options: dict[str, Any] | None) -> tuple[np.ndarray, np.ndarray]:
        """
        :param rng: the random generator
        :param options: ``reset`` options: ``start`` and ``goal`` (xy) place them, else each is drawn by
            :meth:`sample_free` (the start first), or with ``across`` by :meth:`sample_below_gap`: the start on a side
            drawn at random, the goal on the other side than the start
        :return: start and goal xy
        """
        options = options or {}
        if "start" in options:
            start = np.array(options["start"], dtype=float)
        else:
            start = self.sample_below_gap(rng, rng.choice((-1.0, 1.0))) if self.across else self.sample_free(rng)
        if "goal" in options:
            goal = np.array(options["goal"], dtype=float)
        else:
            goal = self.sample_below_gap(rng, -1.0 if start[0] >= 0 else 1.0) if self.across else self.sample_free(rng)
        return start, goal


class WallMazeMap:
    """
    The walled maze as the map of a kinematic body in it (the point of ``Pilot/WallMaze2D-v0``, the car of
    ``Pilot/WallMaze2DCar-v0``), in place of the U-maze of the body's task: the episode's start and goal, where a move
    ends, the goal space and the success distance.
    """

    goal_space_id = WALL_MAZE_GOAL_SPACE
    maze: WallMaze
    distance_threshold: float
    np_random: np.random.Generator

    def _set_map(self, maze_kwargs: dict[str, Any]) -> None:
        """:param maze_kwargs: the map's options (:class:`WallMaze`'s arguments)"""
        self.maze = WallMaze(**maze_kwargs)
        self.distance_threshold = WALL_MAZE_DISTANCE_THRESHOLD

    def _start_and_goal(self, options: dict[str, Any] | None) -> tuple[np.ndarray, np.ndarray]:
        """The episode's start and goal xy (:meth:`WallMaze.start_and_goal`)."""
        return self.maze.start_and_goal(self.np_random, options)

    def _move(self, position: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """Where a move by ``delta`` from ``position`` ends (:meth:`WallMaze.move`)."""
        return self.maze.move(position, delta)


class WallMaze2DEnv(WallMazeMap, Maze2DEnv):
    """
    ``Pilot/WallMaze2D-v0``: :class:`~sb3_pilot.envs.maze.Maze2DEnv`'s point in the walled maze (:class:`WallMaze`),
    moving kinematically by ``step_size * clip(action, -1, 1)`` a step. To go from one lower half to the other, it must
    go up around the wall through the gap. Starts and goals are uniform off the wall (:meth:`WallMaze.start_and_goal`;
    ``reset(options={"start": xy, "goal": xy})`` places them). Observation, achieved goal: the position (2); success
    within 0.1.

    :param step_size: largest displacement per axis and step
    :param render_mode: unsupported (must be None)
    :param maze_kwargs: the map's options, :class:`WallMaze`'s arguments (``gap_y``, ``wall_half_width``, ``slide``,
        ``wall``, ``across``)
    """

    def __init__(self, step_size: float = 0.2, render_mode: str | None = None, **maze_kwargs: Any):
        if not 0 < step_size < 1:
            raise ValueError(f"step_size must be in (0, 1), got {step_size!r}")
        super().__init__(step_size=step_size, render_mode=render_mode)
        self._set_map(maze_kwargs)
        self.observation_space = goal_observation_space(spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32), 2)


class WallMaze2DCarEnv(WallMazeMap, Maze2DCarEnv):
    """
    ``Pilot/WallMaze2DCar-v0``: :class:`~sb3_pilot.envs.car.Maze2DCarEnv`'s car (turn by ``max_turn * a[1]``, then
    move ``max_speed * a[0]`` along the heading) in the walled maze of ``Pilot/WallMaze2D-v0``, with its starts, goals
    and success distance; the initial heading is uniform. Observation: ``(x, y, cos theta, sin theta)`` (4); achieved
    goal: the position (2). A planner distilled on the point plans for it (one goal space).

    :param max_speed: largest move per step (the point moves up to 0.2 per axis)
    :param max_turn: largest turn per step, in radians
    :param render_mode: unsupported (must be None)
    :param maze_kwargs: the map's options, :class:`WallMaze`'s arguments (``gap_y``, ``wall_half_width``, ``slide``,
        ``wall``, ``across``)
    """

    def __init__(
        self, max_speed: float = 0.2, max_turn: float = np.pi / 4, render_mode: str | None = None, **maze_kwargs: Any
    ):
        if not 0 < max_speed < 1:
            raise ValueError(f"max_speed must be in (0, 1), got {max_speed!r}")
        super().__init__(max_speed=max_speed, max_turn=max_turn, render_mode=render_mode)
        self._set_map(maze_kwargs)
