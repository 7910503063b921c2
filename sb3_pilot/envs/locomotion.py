"""
The locomotion tasks: ``Pilot/PointLocomotion-v0`` and ``Pilot/AntLocomotion-v0`` / ``-v1``.

Both robots start at the origin of the same open ground, facing +x, and share one goal distribution
(:func:`sample_locomotion_goal`): an xy uniform over the disk of radius ``LOCOMOTION_GOAL_RADIUS`` = 2
around the start, which the Ant can reach in its 100-step episode. Success within 0.1.

Two Ants (:data:`ANT_XML_FILES`): ``v0`` is gymnasium's (``ant.xml``: gear 150, control range [-1, 1], timestep
0.01 s, a 0.05 s env step); ``v1`` is the hierarchical-RL literature's (``assets/ant_hrl.xml``, the Ant of HIRO, MEGA
and D4RL's antmaze: up to 30 of torque a joint, a fifth of gymnasium's, timestep 0.02 s, a 0.1 s env step, softer
contacts), which random actions rarely flip. Same bodies, observation (29), goal space and episode length.
"""

from __future__ import annotations

import inspect
import os
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.envs.mujoco.ant_v5 import AntEnv
from gymnasium.envs.mujoco.mujoco_env import MujocoEnv

from sb3_pilot.envs.core import GoalReachingMixin, check_render_mode, goal_observation, goal_observation_space

LOCOMOTION_GOAL_RADIUS = 2.0
#: The goal space of the open-ground tasks (``goal_space_id``): the robot's xy on the plane, Point or Ant
LOCOMOTION_GOAL_SPACE = "Pilot/open-ground-xy"
LOCOMOTION_DISTANCE_THRESHOLD = 0.1
# The Ant of AntLocomotion and AntMaze: gymnasium's ant.xml (gear 150, ctrlrange [-1, 1]) with the
# settings gymnasium-robotics' AntMazeEnv (v5) hard-codes, plus the 27-dim joint-state observation.
ANT_OBS_KWARGS: dict[str, Any] = {"include_cfrc_ext_in_observation": False}
ANT_KWARGS: dict[str, Any] = {
    "exclude_current_positions_from_observation": False,
    "reset_noise_scale": 0.0,
    **ANT_OBS_KWARGS,
}
ANT_OBS_DIM = 29  # xy (2) + z, orientation, joint angles (13) + velocities (14)
POINT_XML = os.path.join(os.path.dirname(__file__), "assets", "point.xml")
#: The Ants by name (``ant`` of :class:`AntLocomotionEnv` and of :class:`~sb3_pilot.envs.maze.AntMazeEnv`): gymnasium's
#: ``ant.xml`` (the ``-v0`` tasks) and the hierarchical-RL literature's ``assets/ant_hrl.xml`` (the ``-v1`` tasks)
ANT_XML_FILES: dict[str, str] = {
    "gymnasium": os.path.join(os.path.dirname(inspect.getfile(AntEnv)), "assets", "ant.xml"),
    "hrl": os.path.join(os.path.dirname(__file__), "assets", "ant_hrl.xml"),
}
#: Env steps per second of each Ant (5 MuJoCo steps of 0.01 s, of 0.02 s), MuJoCo's check of ``render_fps``
_ANT_RENDER_FPS: dict[str, int] = {"gymnasium": 20, "hrl": 10}
_RENDER_MODES = ("human", "rgb_array")


def sample_locomotion_goal(rng: np.random.Generator) -> np.ndarray:
    """
    :param rng: the random generator
    :return: an xy uniform over the disk of radius ``LOCOMOTION_GOAL_RADIUS`` centred on the start (origin)
    """
    radius = LOCOMOTION_GOAL_RADIUS * np.sqrt(rng.uniform())
    angle = rng.uniform(-np.pi, np.pi)
    return radius * np.array([np.cos(angle), np.sin(angle)])


class PointLocomotionEnv(GoalReachingMixin, MujocoEnv):
    """
    ``Pilot/PointLocomotion-v0``: a MuJoCo point robot with a heading (``assets/point.xml``) on open ground.

    As the point robot of HIRO/MapGo, it moves kinematically: the action (in [-1, 1]^2) turns the heading
    by ``0.25 * action[1]`` rad, then moves the point by ``forward_step * action[0]`` (0.05 world units by
    default) along the new heading; MuJoCo holds the state and renders it. dt is the Ant's (0.05 s).
    Observation (6, as Table 1): ``x, y, cos(heading), sin(heading), vx, vy``; achieved goal: xy.

    :param forward_step: largest forward displacement per step, in world units
    :param render_mode: ``"rgb_array"``, ``"human"`` or None
    """

    metadata: dict[str, Any] = {"render_modes": list(_RENDER_MODES), "render_fps": 20}  # noqa: RUF012
    goal_space_id = LOCOMOTION_GOAL_SPACE
    max_turn = 0.25

    def __init__(self, forward_step: float = 0.05, render_mode: str | None = None):
        check_render_mode(render_mode, _RENDER_MODES)
        if forward_step <= 0:
            raise ValueError(f"forward_step must be positive, got {forward_step!r}")
        self.forward_step = forward_step
        self.distance_threshold = LOCOMOTION_DISTANCE_THRESHOLD
        self.goal = np.zeros(2)
        obs_space = goal_observation_space(spaces.Box(-np.inf, np.inf, shape=(6,), dtype=np.float32), 2)
        camera = {"distance": 7.0, "elevation": -90.0, "azimuth": 90.0, "lookat": np.zeros(3)}
        MujocoEnv.__init__(self, POINT_XML, 5, obs_space, render_mode=render_mode, default_camera_config=camera)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self._target_site = self.model.site("target").id

    def _get_obs(self) -> dict[str, np.ndarray]:
        x, y, heading = self.data.qpos
        vx, vy, _ = self.data.qvel
        observation = np.array([x, y, np.cos(heading), np.sin(heading), vx, vy], dtype=np.float32)
        return goal_observation(observation, observation[:2], self.goal)

    def reset_model(self) -> dict[str, np.ndarray]:
        self.goal = sample_locomotion_goal(self.np_random)
        self.model.site_pos[self._target_site, :2] = self.goal
        self.set_state(self.init_qpos, self.init_qvel)
        return self._get_obs()

    def _get_reset_info(self) -> dict[str, Any]:
        return self._goal_reward_info(self._get_obs())[1]

    def step(self, action: np.ndarray):
        forward, turn = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0) * [self.forward_step, self.max_turn]
        x, y, heading = self.data.qpos
        heading = (heading + turn + np.pi) % (2 * np.pi) - np.pi
        delta = forward * np.array([np.cos(heading), np.sin(heading)])
        self.set_state(np.array([x + delta[0], y + delta[1], heading]), np.append(delta, turn) / self.dt)
        obs = self._get_obs()
        reward, info = self._goal_reward_info(obs)
        if self.render_mode == "human":
            self.render()
        return obs, reward, False, False, info


def ant_up_z(qpos: np.ndarray) -> float:
    """
    :param qpos: the Ant's ``qpos`` (free joint first: xyz, then the torso's quaternion ``w, x, y, z``)
    :return: z component of the torso's up axis in the world: 1 upright, negative once flipped onto its back
    """
    _, qx, qy, _ = qpos[3:7]
    return float(1.0 - 2.0 * (qx * qx + qy * qy))


REWARD_TYPES = ("sparse", "dense")


def ant_xml_file(ant: str) -> str:
    """
    :param ant: a name of :data:`ANT_XML_FILES` (``"gymnasium"``: the ``-v0`` tasks' Ant; ``"hrl"``: the ``-v1`` tasks')
    :return: the path of that Ant's MuJoCo file
    """
    if ant not in ANT_XML_FILES:
        raise ValueError(f"ant must be one of {sorted(ANT_XML_FILES)}, got {ant!r}")
    return ANT_XML_FILES[ant]


#: What tells the Ants apart in a built env: each named Ant's motors' gear and MuJoCo timestep
_ANT_DYNAMICS: dict[str, tuple[float, float]] = {"gymnasium": (150.0, 0.01), "hrl": (30.0, 0.02)}


def ant_of(env: Any) -> str | None:
    """
    Which Ant an env simulates, read from its MuJoCo model (on the unwrapped env, or on its ``ant_env`` as in
    gymnasium-robotics' ``AntMaze``): its motors' gear and timestep.

    :param env: a Gymnasium env (wrapped or not)
    :return: the Ant's name in :data:`ANT_XML_FILES`, or None for an env of no Ant (or of another Ant)
    """
    task = getattr(env, "unwrapped", env)
    model = getattr(getattr(task, "ant_env", task), "model", None)
    if model is None or model.nu != 8 or model.nq != 15:
        return None
    dynamics = (float(model.actuator_gear[0, 0]), float(model.opt.timestep))
    return next((name for name, known in _ANT_DYNAMICS.items() if np.allclose(known, dynamics)), None)


def check_same_ant(controller_task: Any, guided_task: Any, controller_name: str = "the controller") -> None:
    """
    Refuse to guide a controller on another Ant than the one it was trained on (``-v0`` and ``-v1`` tasks look alike:
    same observation and action spaces, other dynamics).

    :param controller_task: the env the controller trained on (as rebuilt from its run's settings)
    :param guided_task: the env it is to act in
    :param controller_name: how to name the controller in the error (e.g. its file)
    :raises ValueError: if both simulate a known Ant and the two differ
    """
    trained, guided = ant_of(controller_task), ant_of(guided_task)
    if trained is not None and guided is not None and trained != guided:
        raise ValueError(
            f"{controller_name} was trained on {trained!r}'s Ant ({ANT_XML_FILES[trained]}) but the task to guide "
            f"simulates {guided!r}'s ({ANT_XML_FILES[guided]}): their dynamics differ (Pilot/...-v0: 'gymnasium', "
            "Pilot/...-v1: 'hrl'). Guide it on a task of its own Ant, or train a controller on this one."
        )


class AntLocomotionEnv(GoalReachingMixin, AntEnv):
    """
    ``Pilot/AntLocomotion-v0`` (``-v1``): gymnasium's Ant (the literature's, ``ant="hrl"``) on open ground.

    Built with ``ANT_KWARGS``, the arguments gymnasium-robotics' AntMaze passes to its Ant, so that
    ``Pilot/AntMaze-v0`` (``-v1``) has the same Ant: motors, masses and timing. Observation: the Ant's xy (2)
    followed by the rest of its joint state (27) = 29; achieved goal: xy. Falling over does not end the episode.

    The keyword options below train a controller for landmark guidance (``--env-kwargs`` of the zoo, with
    ``max_episode_steps`` for longer episodes); their defaults are the task above, unchanged.

    :param render_mode: ``"rgb_array"``, ``"human"`` or None
    :param ant: which Ant, a name of :data:`ANT_XML_FILES` (``"gymnasium"``: ``-v0``; ``"hrl"``: ``-v1``)
    :param goal_range: None: goals uniform over the disk of radius 2 around the origin (the task above);
        ``(low, high)``: each goal at a distance uniform in ``[low, high]`` from the Ant's current xy, in a
        uniform direction
    :param goal_hold_steps: None: one goal per episode; an integer ``n``: once the goal is reached, it stays
        for ``n`` more steps, then a new goal is drawn around the Ant's position (goals keep moving)
    :param distance_threshold: success radius (0.1 for the task above)
    :param reward_type: ``"sparse"`` (0 on success, else -1, the task above) or ``"dense"``: the progress
        towards the goal in units per second, plus ``upright_reward`` while not flipped, plus
        ``goal_reward`` while the goal is reached, minus ``ctrl_cost_weight * ||action||^2``, all positive
        terms so that ending the episode is never attractive. ``compute_reward`` stays the sparse reward of
        the goals (for HER); the dense reward is for training without relabelling
    :param upright_reward: dense reward per step while the Ant is not flipped
    :param goal_reward: dense reward per step while the goal is reached
    :param ctrl_cost_weight: weight of the squared action in the dense reward
    :param terminate_when_flipped: end the episode (``terminated``) once the Ant is flipped
    :param flip_up_z: the Ant counts as flipped (``info["flipped"]``, no ``upright_reward``, the end of the
        episode with ``terminate_when_flipped``) once the z component of its torso's up axis is below this
        (``ant_up_z``; 0: on its side or back; 0.5: tilted more than 60 degrees)
    :param reset_noise_scale: noise on the initial joint state (AntMaze's Ant: 0)
    """

    metadata: dict[str, Any] = {"render_modes": list(_RENDER_MODES), "render_fps": 20}  # noqa: RUF012
    goal_space_id = LOCOMOTION_GOAL_SPACE

    def __init__(
        self,
        render_mode: str | None = None,
        ant: str = "gymnasium",
        goal_range: tuple[float, float] | None = None,
        goal_hold_steps: int | None = None,
        distance_threshold: float = LOCOMOTION_DISTANCE_THRESHOLD,
        reward_type: str = "sparse",
        upright_reward: float = 1.0,
        goal_reward: float = 1.0,
        ctrl_cost_weight: float = 0.5,
        terminate_when_flipped: bool = False,
        flip_up_z: float = 0.0,
        reset_noise_scale: float = 0.0,
    ):
        check_render_mode(render_mode, _RENDER_MODES)
        xml_file = ant_xml_file(ant)
        if goal_range is not None:
            goal_range = (float(goal_range[0]), float(goal_range[1]))
            if not 0 <= goal_range[0] <= goal_range[1]:
                raise ValueError(f"goal_range must be (low, high) with 0 <= low <= high, got {goal_range!r}")
        if goal_hold_steps is not None and goal_hold_steps < 0:
            raise ValueError(f"goal_hold_steps must be >= 0 or None, got {goal_hold_steps!r}")
        if distance_threshold <= 0:
            raise ValueError(f"distance_threshold must be positive, got {distance_threshold!r}")
        if reward_type not in REWARD_TYPES:
            raise ValueError(f"reward_type must be one of {REWARD_TYPES}, got {reward_type!r}")
        if not -1.0 <= flip_up_z < 1.0:
            raise ValueError(f"flip_up_z must lie in [-1, 1), got {flip_up_z!r}")
        self.ant = ant
        self.goal_range = goal_range
        self.goal_hold_steps = goal_hold_steps
        self.distance_threshold = float(distance_threshold)
        self.reward_type = reward_type
        self.upright_reward = upright_reward
        self.goal_reward = goal_reward
        self.terminate_when_flipped = terminate_when_flipped
        self.flip_up_z = float(flip_up_z)
        self.goal = np.zeros(2)
        self._steps_at_goal = 0
        self.goals_reached = 0
        ant_kwargs = {**ANT_KWARGS, "reset_noise_scale": reset_noise_scale}
        self.metadata = {**type(self).metadata, "render_fps": _ANT_RENDER_FPS[ant]}
        AntEnv.__init__(self, xml_file, render_mode=render_mode, ctrl_cost_weight=ctrl_cost_weight, **ant_kwargs)
        obs_space = spaces.Box(-np.inf, np.inf, shape=(ANT_OBS_DIM,), dtype=np.float32)
        self.observation_space = goal_observation_space(obs_space, 2)

    def _sample_goal(self, position: np.ndarray) -> np.ndarray:
        if self.goal_range is None:
            return sample_locomotion_goal(self.np_random)
        distance = self.np_random.uniform(*self.goal_range)
        angle = self.np_random.uniform(-np.pi, np.pi)
        return np.asarray(position[:2], dtype=np.float64) + distance * np.array([np.cos(angle), np.sin(angle)])

    def _get_obs(self) -> dict[str, np.ndarray]:
        ant_obs = AntEnv._get_obs(self).astype(np.float32)
        return goal_observation(ant_obs, ant_obs[:2], self.goal)

    def reset_model(self) -> dict[str, np.ndarray]:
        self._steps_at_goal, self.goals_reached = 0, 0
        if self.goal_range is None:  # the task's own order of random draws: goal, then the Ant's noise
            self.goal = sample_locomotion_goal(self.np_random)
            return AntEnv.reset_model(self)
        AntEnv.reset_model(self)
        self.goal = self._sample_goal(self.data.qpos[:2])
        return self._get_obs()

    def _get_reset_info(self) -> dict[str, Any]:
        return self._goal_reward_info(self._get_obs())[1]

    @property
    def flipped(self) -> bool:
        """Whether the z component of the torso's up axis is below ``flip_up_z``."""
        return ant_up_z(self.data.qpos) < self.flip_up_z

    @property
    def _options_set(self) -> bool:
        """Whether any guidance-training option differs from the task's default."""
        return (
            self.goal_range is not None
            or self.goal_hold_steps is not None
            or self.reward_type != "sparse"
            or self.terminate_when_flipped
        )

    def step(self, action: np.ndarray):
        previous_distance = self.distance_to_goal()
        self.do_simulation(action, self.frame_skip)
        obs = self._get_obs()
        reward, info = self._goal_reward_info(obs)
        terminated = False
        if self._options_set:
            flipped = self.flipped
            info["flipped"] = flipped
            if self.reward_type == "dense":
                progress = (previous_distance - self.distance_to_goal()) / self.dt
                reward = (
                    progress
                    + self.upright_reward * float(not flipped)
                    + self.goal_reward * float(info["is_success"])
                    - float(self.control_cost(action))
                )
            terminated = bool(self.terminate_when_flipped and flipped)
            if info["is_success"] and self.goal_hold_steps is not None:
                self._steps_at_goal += 1
                if self._steps_at_goal > self.goal_hold_steps:  # a new goal, seen from this observation on
                    self.goals_reached += 1
                    self._steps_at_goal = 0
                    self.goal = self._sample_goal(self.data.qpos[:2])
                    obs = self._get_obs()
            info["goals_reached"] = self.goals_reached
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, False, info

    def distance_to_goal(self) -> float:
        """:return: distance from the Ant's xy to the current goal"""
        return float(np.linalg.norm(np.asarray(self.data.qpos[:2], dtype=np.float64) - self.goal))
