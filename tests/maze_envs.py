"""Tiny kinematic maze and trained teachers for the tests of the distillation and transfer stages."""

import functools
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.monitor import Monitor

from sb3_pilot import UDPO
from sb3_pilot.distill import GoalPlanner


class WallMazeEnv(gym.Env):
    """
    A point in ``[-1, 1]^2`` that moves kinematically (``p <- p + step_size * clip(a, -1, 1)``) with a wall along
    ``x = 0`` from ``y = -1`` up to ``y = gap_y``: to go from one side to the other at low ``y``, the point must go
    around the wall through the gap. A move that would cross (or end in) the wall leaves the point where it is, or,
    with ``slide``, keeps its part along the wall (``y``) if that one is free, else its part across it (``x``).

    Dict observation: ``observation`` and ``achieved_goal`` are the position, ``desired_goal`` the target, all shifted
    by ``offset`` (to test coordinate conventions). Sparse reward: 0 within ``success_distance``, -1 otherwise.
    ``reset(options={"start": xy, "goal": xy})`` places start and goal (unshifted coordinates); otherwise both are
    drawn uniformly in the free space.

    :param max_episode_steps: episode length (truncation)
    :param step_size: largest move per step
    :param gap_y: the wall covers ``y < gap_y``
    :param success_distance: distance under which the goal counts as reached
    :param offset: shift of every reported coordinate
    :param slide: a blocked move slides along the wall instead of leaving the point where it is
    :param wall_half_width: half the wall's width (default: the class attribute, 0.05)
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012
    wall_half_width = 0.05

    def __init__(
        self,
        max_episode_steps: int = 30,
        step_size: float = 0.2,
        gap_y: float = 0.0,
        success_distance: float = 0.1,
        offset: float = 0.0,
        slide: bool = False,
        wall_half_width: float | None = None,
    ):
        self.max_episode_steps = max_episode_steps
        self.step_size = step_size
        self.gap_y = gap_y
        self.success_distance = success_distance
        self.offset = offset
        self.slide = slide
        if wall_half_width is not None:
            self.wall_half_width = wall_half_width
        box = spaces.Box(-1.0 + offset, 1.0 + offset, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Dict({"observation": box, "achieved_goal": box, "desired_goal": box})
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.position = np.zeros(2)
        self.goal = np.zeros(2)
        self.steps = 0

    def blocked(self, start: np.ndarray, end: np.ndarray) -> bool:
        """Whether the straight move from ``start`` to ``end`` (unshifted) hits the wall."""
        if abs(end[0]) <= self.wall_half_width and end[1] < self.gap_y:
            return True
        if np.sign(start[0]) == np.sign(end[0]):
            return False
        crossing_y = start[1] + (end[1] - start[1]) * (0.0 - start[0]) / (end[0] - start[0])
        return bool(crossing_y < self.gap_y)

    def _sample_free(self) -> np.ndarray:
        while True:
            position = self.np_random.uniform(-0.9, 0.9, size=2)
            if abs(position[0]) > 2 * self.wall_half_width or position[1] > self.gap_y:
                return position

    def _obs(self) -> dict[str, np.ndarray]:
        position = (self.position + self.offset).astype(np.float32)
        return {
            "observation": position,
            "achieved_goal": position.copy(),
            "desired_goal": (self.goal + self.offset).astype(np.float32),
        }

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = options or {}
        self.position = np.array(options["start"], dtype=float) if "start" in options else self._sample_free()
        self.goal = np.array(options["goal"], dtype=float) if "goal" in options else self._sample_free()
        self.steps = 0
        return self._obs(), {}

    def step(self, action: np.ndarray):
        target = np.clip(self.position + self.step_size * np.clip(action, -1.0, 1.0), -1.0, 1.0)
        if not self.blocked(self.position, target):
            self.position = target
        elif self.slide:  # the move along the wall (y), else across it (x), else none
            for partial in (np.array([self.position[0], target[1]]), np.array([target[0], self.position[1]])):
                if not self.blocked(self.position, partial):
                    self.position = partial
                    break
        self.steps += 1
        obs = self._obs()
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], {}))
        return obs, reward, False, self.steps >= self.max_episode_steps, {"is_success": reward == 0.0}

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        distance = np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)
        return -(distance > self.success_distance).astype(np.float32)


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
    plan_target: str = "buffer",
) -> UDPO:
    """
    UDPO + HER with the small settings that solve the tiny test envs (cached per process).

    :param env_class: the env
    :param total_timesteps: env steps
    :param seed: the seed
    :param planner_coef: lambda (1e-2, the paper's, is what the point-env tests were written with); None: UDPO's
        default
    :param plan_target: what the planner's likelihood term fits
    """
    lambda_kwargs = {} if planner_coef is None else {"planner_coef": planner_coef}
    model = UDPO(
        "MultiInputPolicy",
        Monitor(env_class()),
        **SMALL_HER_SETTINGS,
        **UDPO_SETTINGS,
        **lambda_kwargs,
        plan_target=plan_target,
        seed=seed,
    )
    return model.learn(total_timesteps)
