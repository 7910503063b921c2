"""
The Fetch tasks: ``Pilot/FetchReach-v0``, ``Pilot/FetchPush-v0``, their ``HighDim`` variants and
``Pilot/FetchReachImage-v0``, all built on gymnasium-robotics' ``FetchReach-v4`` and ``FetchPush-v4``.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sb3_pilot.envs.core import (
    GoalReachingMixin,
    ImageRenderer,
    check_render_mode,
    goal_observation,
    goal_observation_space,
    image_space,
)

FETCH_TASKS = ("reach", "push")
HIGH_DIM_GRAVITY_SCALE = 0.8
# A closer, higher view than gymnasium-robotics' default: the gripper's goal box fills a 64x64 image.
IMAGE_CAMERA_CONFIG: dict[str, Any] = {
    "distance": 1.1,
    "azimuth": 180.0,
    "elevation": -45.0,
    "lookat": np.array([1.34, 0.75, 0.55]),
}


def high_dim_action_transform(action: np.ndarray) -> np.ndarray:
    """
    The High-Dim action dynamics of the paper's appendix, ``h(a)`` for ``n = 2m`` action dimensions.

    The paper prints ``h = - exp(a[0:n/2] + 1) + exp(a[n/2:-1])) / 1.5``, with one unmatched parenthesis
    and a slice ``a[n/2:-1]`` that, read literally, holds ``m - 1`` elements. We read it as the only
    well-formed, same-size version: ``h(a) = (-exp(a[:m] + 1) + exp(a[m:])) / 1.5``, i.e. the whole
    difference divided by 1.5 and the second half running to the end. Actions are first clipped to
    [-1, 1] and ``h`` is clipped to the source bounds [-1, 1]. Note that ``h(0) = (1 - e) / 1.5 < -1``:
    only actions with ``a[m + i] > a[i] + 1`` produce a positive source action.

    :param action: array of shape (..., 2m)
    :return: the source action, of shape (..., m), in [-1, 1]
    """
    action = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    half = action.shape[-1] // 2
    return np.clip((-np.exp(action[..., :half] + 1.0) + np.exp(action[..., half:])) / 1.5, -1.0, 1.0)


class FetchEnv(GoalReachingMixin, gym.Env):
    """
    A gymnasium-robotics Fetch task (``MujocoFetchReachEnv`` or ``MujocoFetchPushEnv``) with the PILoT reward.

    Observation (10 for reach, 25 for push), goal (3), goal distribution and 0.05 success distance are
    gymnasium-robotics'; the goal counts as reached at ``distance <= 0.05`` (gymnasium-robotics: ``<``).

    ``high_dim``: the action has 8 dimensions, mapped to the 4 of the source by
    :func:`high_dim_action_transform`, and gravity is 80% of the original (``model.opt.gravity``).
    ``image_size``: the ``observation`` entry is the uint8 ``image_size x image_size x 3`` frame rendered
    off-screen (``IMAGE_CAMERA_CONFIG``, the target drawn in red unless ``show_target`` is False), the goals stay
    3D vectors. ``antialias=False`` draws those frames without multisampling: about 3x cheaper on CPU rendering
    (osmesa), the same scene with unsmoothed edges (``docs/results/speed.md``); ``Pilot/FetchReachImage-v0``'s frames
    keep it (the default), so that its committed runs re-create: ask for cheap frames with
    ``env_kwargs: {antialias: false}``.

    :param task: ``"reach"`` or ``"push"``
    :param high_dim: use the High-Dim action dynamics and gravity
    :param image_size: None for the vector observation, else the side of the rendered image (>= 16)
    :param render_mode: ``"rgb_array"``, ``"human"`` (vector observation only) or None
    :param show_target: whether rendered frames draw the target (False: the goal is in ``desired_goal`` only, so a
        frame never shows another target than a relabelled goal)
    :param antialias: whether image frames are drawn with 4x multisampling (see above; image tasks only)
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 25}  # noqa: RUF012

    def __init__(
        self,
        task: str = "reach",
        high_dim: bool = False,
        image_size: int | None = None,
        render_mode: str | None = None,
        show_target: bool = True,
        antialias: bool = True,
    ):
        from gymnasium_robotics.envs.fetch.push import MujocoFetchPushEnv
        from gymnasium_robotics.envs.fetch.reach import MujocoFetchReachEnv

        if task not in FETCH_TASKS:
            raise ValueError(f"task must be one of {FETCH_TASKS}, got {task!r}")
        if image_size is None and not antialias:
            raise ValueError("antialias=False is an image task's option (image_size); vector observations draw no frames.")
        fetch_class = MujocoFetchReachEnv if task == "reach" else MujocoFetchPushEnv
        if image_size is None:
            check_render_mode(render_mode, ("human", "rgb_array"))
            self.fetch = fetch_class(render_mode=render_mode)
            obs_space = self.fetch.observation_space["observation"]
            obs_space = spaces.Box(-np.inf, np.inf, shape=obs_space.shape, dtype=np.float32)
        else:
            check_render_mode(render_mode, ("rgb_array",))
            obs_space = image_space(image_size)
            self.fetch = fetch_class()
        self.task = task
        self.high_dim = high_dim
        self.image_size = image_size
        self.render_mode = render_mode
        self.distance_threshold = self.fetch.distance_threshold
        n_actions = self.fetch.action_space.shape[0]
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2 * n_actions if high_dim else n_actions,), dtype=np.float32)
        self.observation_space = goal_observation_space(obs_space, 3)
        if high_dim:
            self.fetch.model.opt.gravity[:] *= HIGH_DIM_GRAVITY_SCALE
        if not show_target:
            self.fetch.model.site_rgba[self.fetch.model.site("target0").id, 3] = 0.0  # MuJoCo draws no site of alpha 0
        self.image_renderer = (
            None if image_size is None else ImageRenderer(self.fetch.model, image_size, IMAGE_CAMERA_CONFIG, antialias)
        )

    @property
    def goal_space_id(self) -> str:  # type: ignore[override]
        """The gripper's position (reach) or the object's (push), whatever the actions and observations."""
        return f"Pilot/Fetch-{self.task}-xyz"

    @property
    def model(self) -> Any:
        """The ``MjModel`` of the Fetch task."""
        return self.fetch.model

    @property
    def data(self) -> Any:
        """The ``MjData`` of the Fetch task."""
        return self.fetch.data

    def _get_obs(self, fetch_obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        observation = fetch_obs["observation"].astype(np.float32) if self.image_renderer is None else self._render_image()
        return goal_observation(observation, fetch_obs["achieved_goal"], fetch_obs["desired_goal"])

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        fetch_obs, _ = self.fetch.reset(seed=seed, options=options)
        obs = self._get_obs(fetch_obs)
        return obs, self._goal_reward_info(obs)[1]

    def step(self, action: np.ndarray):
        action = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        if self.high_dim:
            action = high_dim_action_transform(action)
        fetch_obs, *_ = self.fetch.step(action)
        obs = self._get_obs(fetch_obs)
        reward, info = self._goal_reward_info(obs)
        return obs, reward, False, False, info

    def _render_image(self) -> np.ndarray:
        self.fetch._render_callback()  # gymnasium-robotics' pre-render hook: moves the target site to the goal
        return self.image_renderer.render(self.data)

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        return self.fetch.render() if self.image_renderer is None else self._render_image()

    def close(self) -> None:
        if self.image_renderer is not None:
            self.image_renderer.close()
        self.fetch.close()
