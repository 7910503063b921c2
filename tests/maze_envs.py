"""Tiny kinematic maze and trained teachers for the tests of the distillation and transfer stages."""

import functools
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.monitor import Monitor

from sb3_pilot import UDPO
from sb3_pilot.distill import GoalPlanner
from sb3_pilot.envs.core import goal_observation
from sb3_pilot.envs.wall_maze import WallMaze, WallMaze2DEnv


class WallMazeEnv(WallMaze2DEnv):
    """
    ``Pilot/WallMaze2D-v0``'s point (:class:`~sb3_pilot.envs.wall_maze.WallMaze2DEnv`) as the tests build it without
    ``gym.make``: it truncates its own episodes after ``max_episode_steps``, and ``offset`` shifts every reported
    coordinate (observation, goals; to test coordinate conventions), ``reset``'s ``start`` and ``goal`` options staying
    unshifted.

    :param max_episode_steps: episode length (truncation)
    :param offset: shift of every reported coordinate
    :param kwargs: the task's arguments (``step_size``, ``gap_y``, ``slide``, ``wall_half_width``)
    """

    wall_half_width = WallMaze().wall_half_width

    def __init__(self, max_episode_steps: int = 30, offset: float = 0.0, **kwargs: Any):
        super().__init__(**kwargs)
        self.max_episode_steps = max_episode_steps
        self.offset = offset
        self.wall_half_width = self.maze.wall_half_width
        self.gap_y = self.maze.gap_y
        self.success_distance = self.distance_threshold
        box = spaces.Box(-1.0 + offset, 1.0 + offset, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Dict({"observation": box, "achieved_goal": box, "desired_goal": box})
        self.steps = 0

    def _get_obs(self) -> dict[str, np.ndarray]:
        position = (self.position + self.offset).astype(np.float32)
        return goal_observation(position, position, self.goal + self.offset)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self.steps = 0
        return super().reset(seed=seed, options=options)

    def step(self, action: np.ndarray):
        obs, reward, terminated, _, info = super().step(action)
        self.steps += 1
        return obs, reward, terminated, self.steps >= self.max_episode_steps, info


#: Start and goal on either side of :class:`WallMazeEnv`'s wall, below its gap (unshifted coordinates)
WALL_START, WALL_GOAL = np.array([-0.5, -0.6], dtype=np.float32), np.array([0.5, -0.6], dtype=np.float32)


def wall_detour_end(model: UDPO) -> tuple[bool, np.ndarray]:
    """
    One deterministic episode of ``model`` from :data:`WALL_START` to :data:`WALL_GOAL` on :class:`WallMazeEnv`:
    whether it reached the goal (round the wall), and where it ended.

    Seeds of the wall test's teacher (UDPO's defaults, ``python -c "from tests.maze_envs import *; [print(s,
    wall_detour_end(train_udpo(WallMazeEnv, 20_000, seed=s, planner_coef=None))) for s in range(4)]"``).
    """
    env = WallMazeEnv()
    obs, _ = env.reset(options={"start": WALL_START, "goal": WALL_GOAL})
    for _ in range(env.max_episode_steps):
        obs, _, _, _, info = env.step(model.predict(obs, deterministic=True)[0])
        if info["is_success"]:
            return True, env.position
    return False, env.position


def wall_landmark_path(planner: GoalPlanner, snap: bool | None = None) -> np.ndarray:
    """A planner's 30 landmarks from :data:`WALL_START` to :data:`WALL_GOAL`, the start first."""
    return np.concatenate([WALL_START[None], planner.plan(WALL_START, WALL_GOAL, horizon=30, snap=snap)])


def wall_crossing_y(path: np.ndarray) -> float:
    """Where a path first crosses ``x = 0`` (the wall's line), NaN if it never does."""
    crossings = np.flatnonzero(np.diff(np.sign(path[:, 0])) != 0)
    if len(crossings) == 0:
        return float("nan")
    (x0, y0), (x1, y1) = path[crossings[0]], path[crossings[0] + 1]
    return float(y0 + (y1 - y0) * x0 / (x0 - x1))


#: The off-policy settings that solve the tiny test envs, UDPO's and SAC's alike.
SMALL_HER_SETTINGS: dict[str, Any] = {
    "replay_buffer_class": HerReplayBuffer,
    "learning_starts": 500,
    "batch_size": 256,
    "gamma": 0.95,
    "learning_rate": 1e-3,
    "policy_kwargs": {"net_arch": [64, 64]},
}

#: UDPO's own settings on top of :data:`SMALL_HER_SETTINGS` (those of :func:`train_udpo`).
UDPO_SETTINGS: dict[str, Any] = {
    "inverse_dynamics_interval": 200,
    "inverse_dynamics_learning_rate": 1e-3,
    "inverse_dynamics_gradient_steps": 50,
}


@functools.cache
def train_udpo(
    env_class: type[gym.Env],
    total_timesteps: int,
    seed: int = 0,
    planner_coef: float | None = 1e-2,
) -> UDPO:
    """
    UDPO + HER with the small settings that solve the tiny test envs (cached per process).

    :param env_class: the env
    :param total_timesteps: env steps
    :param seed: the seed
    :param planner_coef: lambda (1e-2, the paper's, is what the point-env tests were written with); None: UDPO's
        default
    """
    lambda_kwargs = {} if planner_coef is None else {"planner_coef": planner_coef}
    model = UDPO(
        "MultiInputPolicy",
        Monitor(env_class()),
        **SMALL_HER_SETTINGS,
        **UDPO_SETTINGS,
        **lambda_kwargs,
        seed=seed,
    )
    return model.learn(total_timesteps)


#: The wall test's teacher (``test_wall_maze_landmarks_go_around_the_wall``), committed: 20k steps of
#: :func:`train_udpo` on :class:`WallMazeEnv` with UDPO's defaults, seed 2; ``python tests/maze_envs.py`` trains and
#: saves it again (about 3 minutes on a core).
WALL_TEACHER = Path(__file__).parent / "data" / "wall_maze_teacher.zip"


def wall_maze_teacher() -> UDPO:
    """The committed teacher of :data:`WALL_TEACHER`, on a :class:`WallMazeEnv`."""
    return UDPO.load(WALL_TEACHER, env=Monitor(WallMazeEnv()))


if __name__ == "__main__":
    WALL_TEACHER.parent.mkdir(exist_ok=True)
    train_udpo(WallMazeEnv, total_timesteps=20_000, seed=2, planner_coef=None).save(WALL_TEACHER)
    print(f"saved {WALL_TEACHER}")
