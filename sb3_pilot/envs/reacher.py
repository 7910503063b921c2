"""The reacher tasks: ``Pilot/Reacher-v0`` and its rendered twin ``Pilot/ReacherImage-v0``."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv

from sb3_pilot.envs.core import (
    GoalReachingMixin,
    ImageRenderer,
    check_render_mode,
    goal_observation,
    goal_observation_space,
    image_space,
)

REACHER_XML = os.path.join(os.path.dirname(__file__), "assets", "reacher3.xml")
REACHER_GOAL_RADIUS = 0.2
REACHER_DISTANCE_THRESHOLD = 0.02


class ReacherEnv(GoalReachingMixin, MujocoEnv):
    """
    A goal-conditioned planar reacher with three joints (``assets/reacher3.xml``: gymnasium's Reacher with
    three 0.07 links, same gear, damping and timing).

    Reset as gymnasium's Reacher: joint angles uniform in [-0.1, 0.1], velocities in [-0.005, 0.005], and a
    goal uniform over the disk of radius 0.2 (reach: 0.21). Achieved goal: the fingertip's xy; success
    within 0.02. Observation: ``cos(q)`` (3), ``sin(q)`` (3), ``dq`` (3) and the fingertip's xy (2) = 11,
    or, with ``image_size``, an ``image_size x image_size x 3`` uint8 top-down image (the target drawn as
    a red disk of the success radius, unless ``show_target`` is False).

    :param image_size: None for the vector observation, else the side of the rendered image (>= 16)
    :param render_mode: ``"rgb_array"``, ``"human"`` (vector observation only) or None
    :param show_target: whether rendered frames draw the target (False: the goal is in ``desired_goal`` only, so a
        frame never shows another target than a relabelled goal)
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 50}  # noqa: RUF012
    #: the fingertip's xy, with or without image observations
    goal_space_id = "Pilot/Reacher-fingertip-xy"

    def __init__(self, image_size: int | None = None, render_mode: str | None = None, show_target: bool = True):
        self.image_size = image_size
        if image_size is None:
            check_render_mode(render_mode, ("human", "rgb_array"))
            obs_space = spaces.Box(-np.inf, np.inf, shape=(11,), dtype=np.float32)
        else:
            check_render_mode(render_mode, ("rgb_array",))
            obs_space = image_space(image_size)
        self.distance_threshold = REACHER_DISTANCE_THRESHOLD
        self.goal = np.zeros(2)
        MujocoEnv.__init__(
            self,
            REACHER_XML,
            2,
            goal_observation_space(obs_space, 2),
            render_mode=render_mode,
            camera_name="top",
        )
        self._target_site = self.model.site("target").id
        if not show_target:
            self.model.site_rgba[self._target_site, 3] = 0.0  # MuJoCo draws no site of alpha 0
        self._fingertip = self.model.body("fingertip").id
        self.image_renderer = None if image_size is None else ImageRenderer(self.model, image_size, "top")

    def _get_obs(self) -> dict[str, np.ndarray]:
        fingertip = self.data.xpos[self._fingertip, :2]
        if self.image_renderer is None:
            qpos, qvel = self.data.qpos, self.data.qvel
            observation = np.concatenate([np.cos(qpos), np.sin(qpos), qvel, fingertip]).astype(np.float32)
        else:
            observation = self.image_renderer.render(self.data)
        return goal_observation(observation, fingertip, self.goal)

    def reset_model(self) -> dict[str, np.ndarray]:
        radius = REACHER_GOAL_RADIUS
        self.goal = self.np_random.uniform(-radius, radius, size=2)
        while np.linalg.norm(self.goal) >= radius:
            self.goal = self.np_random.uniform(-radius, radius, size=2)
        self.model.site_pos[self._target_site, :2] = self.goal
        qpos = self.init_qpos + self.np_random.uniform(-0.1, 0.1, size=self.model.nq)
        qvel = self.init_qvel + self.np_random.uniform(-0.005, 0.005, size=self.model.nv)
        self.set_state(qpos, qvel)
        return self._get_obs()

    def _get_reset_info(self) -> dict[str, Any]:
        return self._goal_reward_info(self._get_obs())[1]

    def step(self, action: np.ndarray):
        self.do_simulation(np.clip(action, -1.0, 1.0), self.frame_skip)
        obs = self._get_obs()
        reward, info = self._goal_reward_info(obs)
        if self.render_mode == "human":
            self.render()
        return obs, reward, False, False, info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        if self.image_renderer is not None:
            return self.image_renderer.render(self.data)
        return MujocoEnv.render(self)

    def close(self) -> None:
        if self.image_renderer is not None:
            self.image_renderer.close()
        MujocoEnv.close(self)
