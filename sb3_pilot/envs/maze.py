"""
The U-maze tasks: ``Pilot/Maze2D-v0`` (a kinematic 2D point) and ``Pilot/AntMaze-v0`` (gymnasium-robotics' AntMaze).

Both use gymnasium-robotics' ``U_MAZE`` map at AntMaze's scale (``maze_size_scaling=4``): cell ``(row, col)``
has its centre at ``x = 4 * (col + 0.5) - 10``, ``y = 10 - 4 * (row + 0.5)``, so the free corridors are

* top: ``x in [-6, 6], y in [2, 6]`` (cells (1, 1), (1, 2), (1, 3)),
* right: ``x in [2, 6], y in [-2, 2]`` (cell (2, 3)),
* bottom: ``x in [-6, 6], y in [-6, -2]`` (cells (3, 1), (3, 2), (3, 3)),

and a goal planned in Maze2D is an AntMaze goal with no conversion.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sb3_pilot.envs.core import GoalReachingMixin, check_render_mode, goal_observation, goal_observation_space

# gymnasium_robotics.envs.maze.maps.U_MAZE (copied: importing gymnasium_robotics imports MuJoCo)
UMAZE_MAP: tuple[tuple[int, ...], ...] = (
    (1, 1, 1, 1, 1),
    (1, 0, 0, 0, 1),
    (1, 1, 1, 0, 1),
    (1, 0, 0, 0, 1),
    (1, 1, 1, 1, 1),
)
UMAZE_SCALING = 4.0  # AntMazeEnv's maze_size_scaling
UMAZE_START_CELL = (1, 1)  # one end of the U ...
UMAZE_GOAL_CELL = (3, 1)  # ... and the other end: the hard case
# gymnasium-robotics adds U(-0.25, 0.25) * maze_size_scaling to each coordinate of goal and start
UMAZE_POSITION_NOISE = 0.25 * UMAZE_SCALING
MAZE_DISTANCE_THRESHOLD = 1.0
GOAL_DISTRIBUTIONS = ("far", "uniform")
#: The goal space of the U-maze tasks (``goal_space_id``): the xy position in the U-maze, in ``AntMaze_UMaze-v5``'s
#: world coordinates, whatever moves there (a point, a car, the Ant)
UMAZE_GOAL_SPACE = "Pilot/U-maze-xy"

_ROWS, _COLS = len(UMAZE_MAP), len(UMAZE_MAP[0])
_X_CENTER, _Y_CENTER = _COLS / 2 * UMAZE_SCALING, _ROWS / 2 * UMAZE_SCALING
UMAZE_FREE_CELLS: tuple[tuple[int, int], ...] = tuple(
    (row, col) for row in range(_ROWS) for col in range(_COLS) if UMAZE_MAP[row][col] == 0
)


def umaze_cell_to_xy(cell: tuple[int, int]) -> np.ndarray:
    """
    :param cell: ``(row, col)`` index in ``UMAZE_MAP``
    :return: world coordinates of the cell's centre (as ``Maze.cell_rowcol_to_xy``)
    """
    row, col = cell
    return np.array([(col + 0.5) * UMAZE_SCALING - _X_CENTER, _Y_CENTER - (row + 0.5) * UMAZE_SCALING])


_FREE_CENTERS = np.array([umaze_cell_to_xy(cell) for cell in UMAZE_FREE_CELLS])


def umaze_is_free(xy: np.ndarray) -> np.ndarray:
    """
    Whether points lie in the free space of the U-maze: the union of the closed free cells (a point on
    a wall's face is free, a point strictly inside a wall block or outside the map is not).

    :param xy: points of shape (..., 2) in world coordinates
    :return: boolean array of shape (...)
    """
    offset = np.abs(np.asarray(xy, dtype=np.float64)[..., None, :] - _FREE_CENTERS)
    return np.any(np.all(offset <= UMAZE_SCALING / 2, axis=-1), axis=-1)


#: Centres of the U-maze's wall blocks (world coordinates), computed once: every step of a wall-margin source reads them
UMAZE_WALL_CENTERS = np.array(
    [umaze_cell_to_xy((row, col)) for row in range(len(UMAZE_MAP)) for col in range(len(UMAZE_MAP[0])) if UMAZE_MAP[row][col]]
)


def umaze_wall_distance(xy: np.ndarray) -> np.ndarray:
    """
    :param xy: points of shape (..., 2) in the U-maze's world coordinates
    :return: distance of each point to the nearest wall block (0 on a wall's face or inside a wall)
    """
    offset = np.abs(np.asarray(xy, dtype=np.float64)[..., None, :] - UMAZE_WALL_CENTERS) - UMAZE_SCALING / 2
    return np.min(np.linalg.norm(np.maximum(offset, 0.0), axis=-1), axis=-1)


class WallMarginWrapper(gym.Wrapper):
    """
    Source-task option for ``Pilot/Maze2D-v0`` (zoo: ``env_wrapper``): every step that ends within ``margin`` of a
    wall without reaching the goal costs ``1 + cost`` instead of 1. The point robot of Maze2D slides along walls
    at no cost, so its optimal paths (and the landmarks of the planner distilled from it) run diagonally into the
    inner wall; a robot with a body (the Ant, legs about 1 unit from its centre) cannot follow those. The reward is
    a function of the achieved goal (the position) and the goal, so HER relabels it consistently, and the task
    (its ID, goals, observations) stays Maze2D's.

    :param env: ``Pilot/Maze2D-v0``
    :param margin: distance to the walls under which a step costs more
    :param cost: extra cost of such a step
    """

    def __init__(self, env: gym.Env, margin: float = 1.0, cost: float = 1.0):
        super().__init__(env)
        self.margin = margin
        self.cost = cost

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        reward = self.env.get_wrapper_attr("compute_reward")(achieved_goal, desired_goal, info)
        near_wall = umaze_wall_distance(achieved_goal) < self.margin
        return (reward - self.cost * (near_wall & (reward < 0))).astype(np.float32)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        reward = float(self.compute_reward(observation["achieved_goal"], observation["desired_goal"], info))
        return observation, reward, terminated, truncated, info


def sample_umaze_start_goal(rng: np.random.Generator, distribution: str = "far") -> tuple[np.ndarray, np.ndarray]:
    """
    Start and goal positions shared by Maze2D and AntMaze.

    ``"far"`` (default, the paper's hard case): start in cell (1, 1) and goal in cell (3, 1), the two ends
    of the U (about 24 units apart along the corridor). ``"uniform"``: AntMaze_UMaze-v5's own distribution,
    a goal cell uniform among the free cells and a start cell among those whose centre is more than 2 units
    from the goal. Both then add gymnasium-robotics' uniform noise of +-1 unit to each coordinate.

    :param rng: the random generator
    :param distribution: ``"far"`` or ``"uniform"``
    :return: start and goal xy
    """
    if distribution == "far":
        goal_xy = umaze_cell_to_xy(UMAZE_GOAL_CELL)
        start_xy = umaze_cell_to_xy(UMAZE_START_CELL)
        goal = goal_xy + rng.uniform(-UMAZE_POSITION_NOISE, UMAZE_POSITION_NOISE, size=2)
    elif distribution == "uniform":
        goal = _FREE_CENTERS[rng.integers(len(_FREE_CENTERS))] + rng.uniform(
            -UMAZE_POSITION_NOISE, UMAZE_POSITION_NOISE, size=2
        )
        start_xy = goal.copy()
        while np.linalg.norm(start_xy - goal) <= 0.5 * UMAZE_SCALING:
            start_xy = _FREE_CENTERS[rng.integers(len(_FREE_CENTERS))]
    else:
        raise ValueError(f"goal_distribution must be one of {GOAL_DISTRIBUTIONS}, got {distribution!r}")
    start = start_xy + rng.uniform(-UMAZE_POSITION_NOISE, UMAZE_POSITION_NOISE, size=2)
    return start, goal


def _slide_axis(position: np.ndarray, delta: float, axis: int) -> np.ndarray:
    """
    Move a free point along one axis, stopping at the face of the wall it would enter.

    :param position: current free xy
    :param delta: displacement along ``axis`` (smaller than a cell)
    :param axis: 0 for x, 1 for y
    :return: the new free xy
    """
    moved = position.copy()
    moved[axis] += delta
    if umaze_is_free(moved):
        return moved
    # the grid line between the old and the new coordinate is the wall's face
    center = _X_CENTER if axis == 0 else _Y_CENTER
    lines = (moved[axis] + center) / UMAZE_SCALING
    moved[axis] = (np.floor(lines) if delta > 0 else np.ceil(lines)) * UMAZE_SCALING - center
    return moved if umaze_is_free(moved) else position


def umaze_move(position: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """
    Move a free point by ``delta`` in the U-maze, first along x then along y; a move into a wall stops at the
    wall's face, so the point slides along walls (the motion of ``Pilot/Maze2D-v0`` and ``Pilot/Maze2DCar-v0``).

    :param position: current free xy
    :param delta: displacement (each coordinate smaller than a cell)
    :return: the new free xy
    """
    for axis in (0, 1):
        position = _slide_axis(position, float(delta[axis]), axis)
    return position


class UMazeMap:
    """
    The U-maze as the map of a kinematic body in it (the point of ``Pilot/Maze2D-v0``, the car of
    ``Pilot/Maze2DCar-v0``): the episode's start and goal, and where a move ends. A body in another map (the walled
    maze's) takes that map's instead.
    """

    goal_distribution: str
    np_random: np.random.Generator

    def _start_and_goal(self, options: dict[str, Any] | None) -> tuple[np.ndarray, np.ndarray]:
        """The episode's start and goal xy (:func:`sample_umaze_start_goal`; ``options`` unused)."""
        return sample_umaze_start_goal(self.np_random, self.goal_distribution)

    def _move(self, position: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """Where a move by ``delta`` from ``position`` ends (sliding along the walls, :func:`umaze_move`)."""
        return umaze_move(position, delta)


class Maze2DEnv(UMazeMap, GoalReachingMixin, gym.Env):
    """
    ``Pilot/Maze2D-v0``: a point that moves kinematically in the U-maze (pure numpy).

    The position moves by ``step_size * clip(action, -1, 1)`` (0.5 world units per axis and step), first
    along x then along y; a move into a wall stops at the wall's face, so the point slides along walls.
    The shortest path between the two ends of the U takes about 32 steps, within the 50-step episode.
    Observation, achieved goal: the position (2); success within 1.0.

    :param goal_distribution: ``"far"`` or ``"uniform"``, see :func:`sample_umaze_start_goal`
    :param step_size: largest displacement per axis and step, in world units
    :param render_mode: unsupported (must be None)
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012
    goal_space_id = UMAZE_GOAL_SPACE

    def __init__(self, goal_distribution: str = "far", step_size: float = 0.5, render_mode: str | None = None):
        check_render_mode(render_mode, ())
        if goal_distribution not in GOAL_DISTRIBUTIONS:
            raise ValueError(f"goal_distribution must be one of {GOAL_DISTRIBUTIONS}, got {goal_distribution!r}")
        if not 0 < step_size < UMAZE_SCALING:
            raise ValueError(f"step_size must be in (0, {UMAZE_SCALING}), got {step_size!r}")
        self.goal_distribution = goal_distribution
        self.step_size = step_size
        self.distance_threshold = MAZE_DISTANCE_THRESHOLD
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = goal_observation_space(spaces.Box(-np.inf, np.inf, shape=(2,), dtype=np.float32), 2)
        self.position = np.zeros(2)
        self.goal = np.zeros(2)

    def _get_obs(self) -> dict[str, np.ndarray]:
        return goal_observation(self.position.astype(np.float32), self.position, self.goal)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.position, self.goal = self._start_and_goal(options)
        obs = self._get_obs()
        return obs, self._goal_reward_info(obs)[1]

    def step(self, action: np.ndarray):
        # in the action's precision (float32 from SB3's policies); Maze2D's step of 0.5 scales it exactly
        self.position = self._move(self.position, self.step_size * np.clip(action, -1.0, 1.0))
        obs = self._get_obs()
        reward, info = self._goal_reward_info(obs)
        return obs, reward, False, False, info


class AntMazeEnv(GoalReachingMixin, gym.Env):
    """
    ``Pilot/AntMaze-v0`` (``-v1``): gymnasium-robotics' ``AntMaze_UMaze-v5`` with the Ant of
    ``Pilot/AntLocomotion-v0`` (``-v1``: the literature's Ant, ``ant="hrl"``).

    The maze, walls and Ant come from ``gymnasium_robotics.envs.maze.ant_maze_v5.AntMazeEnv`` (built with
    ``include_cfrc_ext_in_observation=False``). Start and goal follow :func:`sample_umaze_start_goal`, as in
    Maze2D, and the goal stays fixed for the episode (``continuing_task`` without goal resampling).
    Observation: the Ant's xy (2) followed by the rest of its joint state (27) = 29; achieved goal: xy;
    success within 1.0 (gymnasium-robotics uses 0.45). Falling over does not end the episode.

    :param goal_distribution: ``"far"`` or ``"uniform"``, see :func:`sample_umaze_start_goal`
    :param render_mode: ``"rgb_array"``, ``"human"`` or None
    :param ant: which Ant, a name of :data:`~sb3_pilot.envs.locomotion.ANT_XML_FILES` (``"gymnasium"``: ``-v0``;
        ``"hrl"``: ``-v1``)
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 20}  # noqa: RUF012
    goal_space_id = UMAZE_GOAL_SPACE

    def __init__(self, goal_distribution: str = "far", render_mode: str | None = None, ant: str = "gymnasium"):
        from gymnasium_robotics.envs.maze.ant_maze_v5 import AntMazeEnv as RoboticsAntMazeEnv

        from sb3_pilot.envs.locomotion import ANT_KWARGS, ANT_OBS_DIM, ant_xml_file

        check_render_mode(render_mode, tuple(self.metadata["render_modes"]))
        xml_file = ant_xml_file(ant)
        if goal_distribution not in GOAL_DISTRIBUTIONS:
            raise ValueError(f"goal_distribution must be one of {GOAL_DISTRIBUTIONS}, got {goal_distribution!r}")
        self.goal_distribution = goal_distribution
        self.ant = ant
        self.distance_threshold = MAZE_DISTANCE_THRESHOLD
        self.render_mode = render_mode
        self.maze_env = RoboticsAntMazeEnv(
            render_mode=render_mode,
            maze_map=[list(row) for row in UMAZE_MAP],
            continuing_task=True,
            reset_target=False,
            xml_file=xml_file,
            include_cfrc_ext_in_observation=ANT_KWARGS["include_cfrc_ext_in_observation"],
        )
        # gymnasium-robotics writes the maze's XML to the temp folder and leaves it there; MuJoCo has read it
        os.remove(self.maze_env.tmp_xml_file_path)
        self.ant_env = self.maze_env.ant_env
        self.action_space = self.ant_env.action_space
        obs_space = spaces.Box(-np.inf, np.inf, shape=(ANT_OBS_DIM,), dtype=np.float32)
        self.observation_space = goal_observation_space(obs_space, 2)

    def _get_obs(self, ant_obs: np.ndarray) -> dict[str, np.ndarray]:
        ant_obs = ant_obs.astype(np.float32)
        return goal_observation(ant_obs, ant_obs[:2], self.goal)

    @property
    def goal(self) -> np.ndarray:
        """The desired xy of the episode."""
        return self.maze_env.goal

    @property
    def model(self) -> Any:
        """The ``MjModel`` of the Ant in the maze."""
        return self.ant_env.model

    @property
    def data(self) -> Any:
        """The ``MjData`` of the Ant in the maze."""
        return self.ant_env.data

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        start, self.maze_env.goal = sample_umaze_start_goal(self.np_random, self.goal_distribution)
        self.maze_env.update_target_site_pos()
        self.ant_env.init_qpos[:2] = start
        ant_obs, _ = self.ant_env.reset(seed=seed)
        obs = self._get_obs(ant_obs)
        return obs, self._goal_reward_info(obs)[1]

    def step(self, action: np.ndarray):
        ant_obs, *_ = self.ant_env.step(action)
        obs = self._get_obs(ant_obs)
        reward, info = self._goal_reward_info(obs)
        return obs, reward, False, False, info

    def render(self) -> np.ndarray | None:
        return self.ant_env.render()

    def close(self) -> None:
        self.maze_env.close()
