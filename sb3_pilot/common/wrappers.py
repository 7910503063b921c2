"""
Gymnasium wrappers for the image tasks, selectable from an RL-Zoo YAML's ``env_wrapper``:

- :class:`ImageFrameStack`: the last frames of the image entry of a goal-conditioned ``Dict`` observation, stacked
  along the channel axis, the goal entries untouched (HER relabels and rewards them as without it).
"""

from __future__ import annotations

from collections import deque
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.preprocessing import is_image_space, is_image_space_channels_first

from sb3_pilot.pixels.encoder import IMAGE_KEY


class ImageFrameStack(gym.Wrapper):
    """
    Stacks the last ``n_frames`` frames of one image entry of a ``Dict`` observation along its channel axis (the
    last axis of a channel-last ``H x W x C`` image, the first of a channel-first one): ``C`` becomes
    ``n_frames * C``, oldest frame first. After a reset the stack holds ``n_frames`` copies of the first frame.

    Every other entry (``achieved_goal``, ``desired_goal``) is left as it is, so HER's relabelling and
    ``compute_reward`` see the task unchanged. RL Zoo's ``frame_stack`` (SB3's ``VecFrameStack``) stacks every entry
    of a ``Dict`` observation, the goals included, which HER cannot relabel.

    From an RL-Zoo YAML::

        env_wrapper:
          - sb3_pilot.common.wrappers.ImageFrameStack:
              n_frames: 3

    :param env: environment with a ``Dict`` observation holding a uint8 image under ``key``
    :param n_frames: number of frames stacked (1: the observation unchanged)
    :param key: the image entry
    """

    def __init__(self, env: gym.Env, n_frames: int = 3, key: str = IMAGE_KEY):
        if not isinstance(n_frames, int) or isinstance(n_frames, bool) or n_frames < 1:
            raise ValueError(f"ImageFrameStack needs n_frames >= 1 frames, got {n_frames!r}.")
        space = env.observation_space
        if not isinstance(space, spaces.Dict) or key not in space.spaces:
            raise ValueError(f"ImageFrameStack needs a Dict observation space with an image entry {key!r}, got {space}.")
        image = space[key]
        if not is_image_space(image, check_channels=False):
            raise ValueError(f"ImageFrameStack stacks images (uint8, height x width x channels): {key!r} is {image}.")
        super().__init__(env)
        assert isinstance(image, spaces.Box)
        self.n_frames = n_frames
        self.key = key
        self._axis = 0 if is_image_space_channels_first(image) else -1
        stacked = spaces.Box(
            low=np.concatenate([image.low] * n_frames, axis=self._axis),
            high=np.concatenate([image.high] * n_frames, axis=self._axis),
            dtype=image.dtype,  # type: ignore[arg-type]
        )
        self.observation_space = spaces.Dict({**space.spaces, key: stacked})
        self._frames: deque[np.ndarray] = deque(maxlen=n_frames)

    def _stacked(self, obs: dict[str, Any]) -> dict[str, Any]:
        return {**obs, self.key: np.concatenate(self._frames, axis=self._axis)}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._frames.extend([obs[self.key]] * self.n_frames)
        return self._stacked(obs), info

    def step(self, action: Any) -> tuple[dict[str, Any], SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._frames.append(obs[self.key])
        return self._stacked(obs), reward, terminated, truncated, info
