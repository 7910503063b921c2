"""A tiny image goal environment for the image-agent tests (pure numpy, fast)."""

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

SIZE = 40  # the smallest round size NatureCNN's 8x8/4, 4x4/2, 3x3/1 convolutions accept


class ImageGoalEnv(gym.Env):
    """A point in [-1, 1]^2 drawn as a bright square on a SIZE x SIZE image; sparse goal reward (numpy, fast)."""

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(self) -> None:
        box2 = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        image = spaces.Box(0, 255, shape=(SIZE, SIZE, 3), dtype=np.uint8)
        self.observation_space = spaces.Dict({"observation": image, "achieved_goal": box2, "desired_goal": box2})
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.position = np.zeros(2, dtype=np.float32)
        self.goal = np.zeros(2, dtype=np.float32)
        self.steps = 0

    def _obs(self) -> dict[str, np.ndarray]:
        image = np.zeros((SIZE, SIZE, 3), dtype=np.uint8)
        row, col = ((self.position + 1) / 2 * (SIZE - 4)).astype(int)
        image[row : row + 4, col : col + 4] = 255
        return {"observation": image, "achieved_goal": self.position.copy(), "desired_goal": self.goal.copy()}

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        return -(np.linalg.norm(achieved_goal - desired_goal, axis=-1) > 0.2).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        self.position = self.np_random.uniform(-1, 1, 2).astype(np.float32)
        self.goal = self.np_random.uniform(-1, 1, 2).astype(np.float32)
        self.steps = 0
        return self._obs(), {}

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        self.position = np.clip(self.position + 0.2 * np.asarray(action, dtype=np.float32), -1, 1)
        self.steps += 1
        obs = self._obs()
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], {}))
        return obs, reward, False, self.steps >= 10, {"is_success": reward == 0.0}
