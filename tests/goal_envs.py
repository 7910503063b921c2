"""Tiny, fast goal environments written for the tests (pure numpy, thousands of steps per second)."""

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces


class PointGoalEnv(gym.Env):
    """
    A 2D point mass in ``[-1, 1]^2`` that must reach a goal: Dict observation, sparse reward (0 on success, -1 else).

    ``observation`` is position and velocity, ``achieved_goal`` the position, ``desired_goal`` the target.
    The action is a force in ``[-1, 1]^2``: ``v <- damping * v + force_scale * a``, ``p <- clip(p + v)``.

    :param max_episode_steps: episode length (truncation)
    :param success_distance: distance under which the goal counts as reached
    :param damping: velocity damping per step
    :param force_scale: velocity change per unit of action
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        max_episode_steps: int = 25,
        success_distance: float = 0.1,
        damping: float = 0.5,
        force_scale: float = 0.1,
    ):
        self.max_episode_steps = max_episode_steps
        self.success_distance = success_distance
        self.damping = damping
        self.force_scale = force_scale
        box2 = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = spaces.Dict(
            {
                "observation": spaces.Box(-np.inf, np.inf, shape=(4,), dtype=np.float32),
                "achieved_goal": box2,
                "desired_goal": box2,
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.position = np.zeros(2)
        self.velocity = np.zeros(2)
        self.goal = np.zeros(2)
        self.steps = 0

    def _obs(self) -> dict[str, np.ndarray]:
        return {
            "observation": np.concatenate([self.position, self.velocity]).astype(np.float32),
            "achieved_goal": self.position.astype(np.float32),
            "desired_goal": self.goal.astype(np.float32),
        }

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.position = self.np_random.uniform(-0.8, 0.8, size=2)
        self.velocity = np.zeros(2)
        self.goal = self.np_random.uniform(-0.8, 0.8, size=2)
        self.steps = 0
        return self._obs(), {}

    def step(self, action: np.ndarray):
        action = np.clip(action, -1.0, 1.0)
        self.velocity = self.damping * self.velocity + self.force_scale * action
        self.position = np.clip(self.position + self.velocity, -1.0, 1.0)
        self.steps += 1
        obs = self._obs()
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], {}))
        info = {"is_success": reward == 0.0}
        return obs, reward, False, self.steps >= self.max_episode_steps, info

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        distance = np.linalg.norm(np.asarray(achieved_goal) - np.asarray(desired_goal), axis=-1)
        return -(distance > self.success_distance).astype(np.float32)
