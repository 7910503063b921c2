"""
The tasks of the PILoT paper's Table 1 as Gymnasium environments (``Pilot/...-v0``), and ``-v1`` of the two Ant
tasks: the same tasks with the hierarchical-RL literature's Ant (:data:`~sb3_pilot.envs.locomotion.ANT_XML_FILES`).

:func:`register_envs` registers them with entry-point strings, so that MuJoCo is only imported when an
environment is made. Every task returns a ``Dict`` observation (``observation``, ``achieved_goal``,
``desired_goal``), a sparse -1/0 reward with a vectorised ``compute_reward`` and ``info["is_success"]``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from sb3_pilot.envs.maze import (
    UMAZE_MAP,
    UMAZE_SCALING,
    sample_umaze_start_goal,
    umaze_cell_to_xy,
    umaze_is_free,
)
from sb3_pilot.envs.wall_maze import WallMaze

# id: (entry point, kwargs, episode length)
PILOT_ENV_SPECS: dict[str, tuple[str, dict[str, Any], int]] = {
    "Pilot/FetchReach-v0": ("sb3_pilot.envs.fetch:FetchEnv", {"task": "reach"}, 50),
    "Pilot/FetchPush-v0": ("sb3_pilot.envs.fetch:FetchEnv", {"task": "push"}, 50),
    "Pilot/FetchReachHighDim-v0": ("sb3_pilot.envs.fetch:FetchEnv", {"task": "reach", "high_dim": True}, 50),
    "Pilot/FetchPushHighDim-v0": ("sb3_pilot.envs.fetch:FetchEnv", {"task": "push", "high_dim": True}, 50),
    "Pilot/FetchReachImage-v0": ("sb3_pilot.envs.fetch:FetchEnv", {"task": "reach", "image_size": 64}, 50),
    "Pilot/Reacher-v0": ("sb3_pilot.envs.reacher:ReacherEnv", {}, 50),
    "Pilot/ReacherImage-v0": ("sb3_pilot.envs.reacher:ReacherEnv", {"image_size": 64}, 50),
    "Pilot/PointLocomotion-v0": ("sb3_pilot.envs.locomotion:PointLocomotionEnv", {}, 500),
    "Pilot/AntLocomotion-v0": ("sb3_pilot.envs.locomotion:AntLocomotionEnv", {}, 100),
    "Pilot/Maze2D-v0": ("sb3_pilot.envs.maze:Maze2DEnv", {}, 50),
    "Pilot/Maze2DCar-v0": ("sb3_pilot.envs.car:Maze2DCarEnv", {}, 50),
    "Pilot/AntMaze-v0": ("sb3_pilot.envs.maze:AntMazeEnv", {}, 500),
    # the two Ant tasks with the hierarchical-RL literature's Ant (HIRO's, D4RL's antmaze): new dynamics, new version
    "Pilot/AntLocomotion-v1": ("sb3_pilot.envs.locomotion:AntLocomotionEnv", {"ant": "hrl"}, 100),
    "Pilot/AntMaze-v1": ("sb3_pilot.envs.maze:AntMazeEnv", {"ant": "hrl"}, 500),
    # beyond the paper: the walled maze, a point (a source) and a car (a target) in one square with a wall to go around
    "Pilot/WallMaze2D-v0": ("sb3_pilot.envs.wall_maze:WallMaze2DEnv", {}, 30),
    "Pilot/WallMaze2DCar-v0": ("sb3_pilot.envs.wall_maze:WallMaze2DCarEnv", {}, 30),
}
PILOT_ENV_IDS: tuple[str, ...] = tuple(PILOT_ENV_SPECS)


#: Names of :mod:`sb3_pilot.envs.locomotion` exported here, imported on first use (it imports MuJoCo)
_LOCOMOTION_NAMES = ("ANT_XML_FILES", "ant_of", "ant_up_z", "check_same_ant")


def __getattr__(name: str) -> Any:
    if name in _LOCOMOTION_NAMES:
        from sb3_pilot.envs import locomotion

        return getattr(locomotion, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register_envs() -> None:
    """Register every ``Pilot/...`` task with Gymnasium (calling it again does nothing)."""
    for env_id, (entry_point, kwargs, max_episode_steps) in PILOT_ENV_SPECS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry_point, kwargs=kwargs, max_episode_steps=max_episode_steps)


__all__ = [
    "ANT_XML_FILES",
    "PILOT_ENV_IDS",
    "PILOT_ENV_SPECS",
    "UMAZE_MAP",
    "UMAZE_SCALING",
    "WallMaze",
    "ant_of",
    "ant_up_z",
    "check_same_ant",
    "register_envs",
    "sample_umaze_start_goal",
    "umaze_cell_to_xy",
    "umaze_is_free",
]
