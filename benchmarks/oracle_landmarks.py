"""
The best a landmark could do: PILoT's bonus with *exact* immediate landmarks on the U-maze tasks, for comparison
with a distilled planner's.

:class:`UMazeOraclePlanner` plans a step of the shortest path around the U-maze's inner wall (no learning, the map
known); :class:`OracleBonusWrapper` is :class:`~sb3_pilot.PilotBonusWrapper` with it. In a challenge stage or a zoo
YAML: ``env_wrapper: [{benchmarks.oracle_landmarks.OracleBonusWrapper: {beta: 1.0}}]`` with
``PilotHerReplayBuffer`` (``zoo_runs/maze-car-progress``).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from sb3_pilot.distill import GoalPlanner
from sb3_pilot.envs import UMAZE_SCALING
from sb3_pilot.transfer import PilotBonusWrapper

#: The U-maze's inner wall (world coordinates): x in [-6, 2], y in [-2, 2] (``sb3_pilot.envs.maze``)
INNER_WALL = np.array([[-1.5 * UMAZE_SCALING, -0.5 * UMAZE_SCALING], [0.5 * UMAZE_SCALING, 0.5 * UMAZE_SCALING]])


def _crosses_inner_wall(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Whether the segments ``start -> end`` (n, 2) pass through the inner wall's interior (Liang-Barsky clipping)."""
    direction = end - start
    with np.errstate(divide="ignore", invalid="ignore"):
        bounds = (INNER_WALL[:, None, :] - start) / direction  # (2, n, 2): the parameters where each face is crossed
    enter, leave = bounds.min(axis=0), bounds.max(axis=0)
    parallel = direction == 0  # a segment parallel to a face: inside that slab throughout, or never
    inside_slab = (start > INNER_WALL[0]) & (start < INNER_WALL[1])
    enter = np.where(parallel, np.where(inside_slab, -np.inf, np.inf), enter)
    leave = np.where(parallel, np.where(inside_slab, np.inf, -np.inf), leave)
    return np.maximum(enter.max(axis=1), 0.0) < np.minimum(leave.min(axis=1), 1.0) - 1e-9


class UMazeOraclePlanner(GoalPlanner):
    """
    Exact immediate landmarks of the U-maze: ``step`` along the shortest path from the achieved goal to the desired
    one, which bends at most at the inner wall's two free corners (``margin`` off them). A
    :class:`~sb3_pilot.GoalPlanner` whose :meth:`predict` ignores its network, so that
    :class:`~sb3_pilot.PilotBonusWrapper` takes it as it is.

    :param step: length of a planned step (world units): the Maze2D point moves at most 0.5 per axis, 0.71 diagonally
    :param margin: distance of the path's bends from the wall's corners
    """

    def __init__(self, step: float = 0.7, margin: float = 0.5):
        super().__init__(2, net_arch=[], metadata={"source_task": "Pilot/Maze2D-v0", "oracle": "U-maze shortest path"})
        self.step = step
        right = INNER_WALL[1, 0] + margin
        self.corners = np.array([[right, INNER_WALL[1, 1] + margin], [right, INNER_WALL[0, 1] - margin]])

    def shortest_path(self, start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """
        The shortest paths ``start -> end`` in the free space, bending at the corners.

        :param start: shape (n, 2)
        :param end: shape (n, 2)
        :return: each path's first waypoint (the end itself, or a corner), shape (n, 2), and its length, shape (n,)
        """
        first, second = (np.broadcast_to(corner, start.shape) for corner in self.corners)

        def length(vector: np.ndarray) -> np.ndarray:
            return np.linalg.norm(vector, axis=-1)

        def clear(a: np.ndarray, b: np.ndarray) -> np.ndarray:
            return ~_crosses_inner_wall(a, b)

        gap = length(self.corners[0] - self.corners[1])
        # (first waypoint, path length, whether every leg is clear): direct, by one corner, by both (either order)
        paths = [
            (end, length(end - start), clear(start, end)),
            (first, length(first - start) + length(end - first), clear(start, first) & clear(first, end)),
            (second, length(second - start) + length(end - second), clear(start, second) & clear(second, end)),
            (first, length(first - start) + gap + length(end - second), clear(start, first) & clear(second, end)),
            (second, length(second - start) + gap + length(end - first), clear(start, second) & clear(first, end)),
        ]
        lengths = np.stack([np.where(is_clear, path_length, np.inf) for _, path_length, is_clear in paths])
        best = np.argmin(lengths, axis=0)
        waypoints = np.stack([waypoint for waypoint, _, _ in paths])
        return waypoints[best, np.arange(len(start))], lengths[best, np.arange(len(start))]

    def predict(
        self, achieved_goal: np.ndarray, desired_goal: np.ndarray, deterministic: bool = True, snap: bool = False
    ) -> np.ndarray:
        """
        The point ``step`` along the shortest path (or the desired goal, if nearer).

        :param achieved_goal: shape (2,) or (n, 2)
        :param desired_goal: same shape
        :param deterministic: unused (the oracle is deterministic)
        :param snap: unused
        """
        start = np.atleast_2d(np.asarray(achieved_goal, dtype=np.float64))
        waypoint, _ = self.shortest_path(start, np.atleast_2d(np.asarray(desired_goal, dtype=np.float64)))
        direction = waypoint - start
        distance = np.linalg.norm(direction, axis=-1)
        landmark = start + direction * np.minimum(1.0, self.step / np.maximum(distance, 1e-8))[:, None]
        return landmark.astype(np.float32).reshape(np.shape(achieved_goal))


class OracleBonusWrapper(PilotBonusWrapper):
    """
    :class:`~sb3_pilot.PilotBonusWrapper` with :class:`UMazeOraclePlanner`'s exact landmarks.

    :param env: a U-maze goal env (``Pilot/Maze2D-v0``, ``Pilot/Maze2DCar-v0``, ...)
    :param beta: bonus ratio ``beta``
    :param similarity: as :class:`~sb3_pilot.PilotBonusWrapper`'s
    :param step: the oracle's step length
    """

    def __init__(self, env: gym.Env, beta: float = 1.0, similarity: str = "displacement_cosine", step: float = 0.7):
        super().__init__(env, UMazeOraclePlanner(step), beta=beta, similarity=similarity)
