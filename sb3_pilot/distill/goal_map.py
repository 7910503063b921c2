"""A known affine map between the goal coordinates of two tasks (:func:`~sb3_pilot.share_goal_space`'s ``goal_map``)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


class GoalMap:
    """
    Affine map between two tasks' goal coordinates, ``g_second = matrix @ g_first + offset``: the goals mean the same
    thing, in other units or with another origin. A goal planner distilled on the first task plans for the second one
    through it (the bonus and the guidance map the second task's goals into the planner's coordinates, plan, and map
    the landmark back).

    Example, gymnasium-robotics' mazes: an ``AntMaze_*`` maze is the ``PointMaze_*`` maze of the same layout with
    ``maze_size_scaling`` 4 instead of 1, both centred on the map, so an ``AntMaze_UMaze-v5`` goal is 4 times the
    ``PointMaze_UMaze-v3`` goal of the same place: ``GoalMap(4.0)``.

    :param matrix: an invertible ``(d, d)`` matrix, a ``(d,)`` scale per coordinate, or one scale for every coordinate
    :param offset: added after the matrix: a ``(d,)`` vector or one number
    """

    def __init__(self, matrix: float | np.ndarray = 1.0, offset: float | np.ndarray = 0.0):
        matrix, offset = np.array(matrix, dtype=np.float64), np.array(offset, dtype=np.float64)
        if matrix.ndim > 2 or (matrix.ndim == 2 and matrix.shape[0] != matrix.shape[1]):
            raise ValueError(f"matrix must be a number, a (d,) scale or a square (d, d) matrix, got shape {matrix.shape}.")
        if offset.ndim > 1:
            raise ValueError(f"offset must be a number or a (d,) vector, got shape {offset.shape}.")
        sizes = {len(matrix)} if matrix.ndim > 0 else set()
        sizes |= {len(offset)} if offset.ndim == 1 else set()
        if len(sizes) > 1:
            raise ValueError(f"matrix (shape {matrix.shape}) and offset (shape {offset.shape}) have different sizes.")
        if not (np.isfinite(matrix).all() and np.isfinite(offset).all()):
            raise ValueError(f"A goal map needs finite numbers, got matrix {matrix} and offset {offset}.")
        singular = np.linalg.matrix_rank(matrix) < len(matrix) if matrix.ndim == 2 else (matrix == 0).any()
        if singular:
            raise ValueError(f"The goal map's matrix must be invertible (the map must go both ways), got {matrix}.")
        self.matrix, self.offset = matrix, offset
        #: the goal size the map is for (None: any)
        self.goal_dim: int | None = next(iter(sizes), None)
        self._inverse: GoalMap | None = None

    def __call__(self, goals: np.ndarray) -> np.ndarray:
        """
        :param goals: goals of the first task, shape (..., d)
        :return: the same goals in the second task's coordinates, same shape
        """
        goals = np.asarray(goals)
        mapped = goals @ self.matrix.T if self.matrix.ndim == 2 else goals * self.matrix
        return (mapped + self.offset).astype(np.result_type(goals.dtype, np.float32))

    def inverse(self) -> GoalMap:
        """The map from the second task's coordinates to the first's."""
        if self._inverse is None:
            if self.matrix.ndim == 2:
                matrix = np.linalg.inv(self.matrix)
                offset = -matrix @ self.offset if self.offset.ndim == 1 else -matrix.sum(axis=1) * self.offset
            else:
                matrix, offset = 1.0 / self.matrix, -self.offset / self.matrix
            self._inverse = GoalMap(matrix, offset)
            self._inverse._inverse = self
        return self._inverse

    def through(
        self, plan: Callable[[np.ndarray, np.ndarray], np.ndarray], achieved_goal: np.ndarray, desired_goal: np.ndarray
    ) -> np.ndarray:
        """
        Plan in the first task's coordinates for goals of the second task.

        :param plan: ``plan(achieved_goal, desired_goal)`` in the first task's coordinates, e.g. ``planner.predict``
        :param achieved_goal: goal(s) of the second task
        :param desired_goal: goal(s) of the second task
        :return: what ``plan`` returns for the goals mapped into the first task's coordinates, mapped back
        """
        to_first = self.inverse()
        return self(plan(to_first(achieved_goal), to_first(desired_goal)))

    def check_goal_dim(self, goal_dim: int) -> None:
        """:raises ValueError: when the map is for goals of another size than ``goal_dim``"""
        if self.goal_dim is not None and self.goal_dim != goal_dim:
            raise ValueError(f"The goal map is for {self.goal_dim}-dim goals, the goals here are {goal_dim}-dim.")

    def __repr__(self) -> str:
        return f"GoalMap(matrix={self.matrix.tolist()}, offset={self.offset.tolist()})"
