"""Shared pieces of the PILoT tasks: the sparse goal-reaching reward, the spaces and off-screen rendering."""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from gymnasium import Env, Wrapper, spaces

if TYPE_CHECKING:
    import torch as th

RENDER_FIX = "install libosmesa6 and set MUJOCO_GL=osmesa (and PYOPENGL_PLATFORM=osmesa)"
MIN_IMAGE_SIZE = 16


class GoalReachingMixin:
    """
    Sparse goal-reaching reward shared by every PILoT task (the ``GoalEnv`` API of gymnasium-robotics).

    A goal counts as reached when ``||achieved_goal - desired_goal|| <= distance_threshold``; the reward is
    then 0, otherwise -1. Tasks never terminate on success: episodes are truncated by the ``TimeLimit`` set
    at registration, as in gymnasium-robotics' Fetch tasks.

    ``goal_space_id`` declares the task's goal space: tasks that declare the same one have goals of the same meaning in
    the same coordinates, so a goal planner distilled on one plans for the others (None: the task's own).
    """

    distance_threshold: float
    goal_space_id: str | None = None

    @staticmethod
    def goal_distance(achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
        """
        Euclidean distance over the last axis, computed in float64.

        :param achieved_goal: goals of shape (..., goal_dim)
        :param desired_goal: goals of the same shape
        :return: distances of shape (...)
        """
        diff = np.asarray(achieved_goal, dtype=np.float64) - np.asarray(desired_goal, dtype=np.float64)
        return np.linalg.norm(diff, axis=-1)

    def is_success(self, achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
        """
        :param achieved_goal: goals of shape (..., goal_dim)
        :param desired_goal: goals of the same shape
        :return: boolean array of shape (...): the goal is within ``distance_threshold``
        """
        return self.goal_distance(achieved_goal, desired_goal) <= self.distance_threshold

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """
        Vectorised sparse reward, as SB3's ``HerReplayBuffer`` expects.

        :param achieved_goal: goals of shape (..., goal_dim)
        :param desired_goal: goals of the same shape
        :param info: unused (one info dict, or an array of them for a batch)
        :return: float32 array of shape (...): 0 where the goal is reached, -1 elsewhere
        """
        return self.is_success(achieved_goal, desired_goal).astype(np.float32) - 1.0

    def compute_reward_torch(self, achieved_goal: th.Tensor, desired_goal: th.Tensor) -> th.Tensor:
        """
        :meth:`compute_reward` on tensors, on their device (a device-resident replay buffer relabels with it): the
        same float64 distance, its squares summed in the order numpy's ``np.linalg.norm`` sums fewer than 8 of them,
        so the rewards are equal, also at the threshold (:func:`torch_reward_twin` offers it for such goals only).

        :param achieved_goal: goals of shape (batch, goal_dim)
        :param desired_goal: goals of the same shape
        :return: float32 tensor of shape (batch,): 0 where the goal is reached, -1 elsewhere
        """
        diff = achieved_goal.double() - desired_goal.double()
        squared = diff[..., 0] * diff[..., 0]
        for dim in range(1, diff.shape[-1]):
            squared = squared + diff[..., dim] * diff[..., dim]
        return (squared.sqrt() <= self.distance_threshold).float() - 1.0

    def compute_terminated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> bool:
        """Reaching the goal does not end the episode."""
        return False

    def compute_truncated(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> bool:
        """Truncation is left to the ``TimeLimit`` wrapper added at registration."""
        return False

    def _goal_reward_info(self, obs: dict[str, np.ndarray]) -> tuple[float, dict[str, Any]]:
        """
        Reward and info of a transition that ended in ``obs``, computed from the float32 goals the
        agent sees, so that ``compute_reward`` on stored transitions gives the same value.

        :param obs: the goal-conditioned observation
        :return: reward and ``{"is_success": bool}``
        """
        info = {"is_success": bool(self.is_success(obs["achieved_goal"], obs["desired_goal"]))}
        return float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)), info


#: Goals of at most this size have a torch twin of ``compute_reward``: numpy sums fewer than 8 terms in order
MAX_TWIN_GOAL_DIM = 7


def torch_reward_twin(env: Env, goal_dim: int) -> Callable[[th.Tensor, th.Tensor], th.Tensor] | None:
    """
    The torch twin of the ``compute_reward`` that ``env.get_wrapper_attr("compute_reward")`` (what SB3's VecEnvs call)
    returns, or None where there is none. There is one when that method is :class:`GoalReachingMixin`'s own, on an
    instance whose class overrides none of ``compute_reward``, ``is_success`` and ``goal_distance``, for goals of at
    most ``MAX_TWIN_GOAL_DIM`` entries: a wrapper or subclass that changes the reward (a reward bonus, a wall cost)
    has no twin, and its rewards are computed by its ``compute_reward``.

    :param env: the env (possibly wrapped)
    :param goal_dim: size of the goal vectors
    :return: ``compute_reward_torch`` of the env that computes the rewards, or None
    """
    owner: Any = env
    while not hasattr(owner, "compute_reward"):
        if not isinstance(owner, Wrapper):
            return None
        owner = owner.env
    if not isinstance(owner, GoalReachingMixin) or goal_dim > MAX_TWIN_GOAL_DIM:
        return None
    cls = type(owner)
    mirrored = ("compute_reward", "is_success", "goal_distance", "compute_reward_torch")
    if any(getattr(cls, name) is not getattr(GoalReachingMixin, name) for name in mirrored):
        return None
    return owner.compute_reward_torch


def goal_observation(observation: np.ndarray, achieved_goal: np.ndarray, desired_goal: np.ndarray) -> dict[str, np.ndarray]:
    """
    :param observation: the ``observation`` entry (a float32 vector or a uint8 image, kept as is)
    :param achieved_goal: the achieved goal
    :param desired_goal: the desired goal
    :return: the goal-conditioned observation, goals as fresh float32 arrays
    """
    return {
        "observation": observation,
        "achieved_goal": np.array(achieved_goal, dtype=np.float32),
        "desired_goal": np.array(desired_goal, dtype=np.float32),
    }


def goal_observation_space(observation: spaces.Box, goal_dim: int) -> spaces.Dict:
    """
    :param observation: the space of the ``observation`` entry (float32 vector or uint8 image)
    :param goal_dim: size of the goal vectors
    :return: the ``Dict`` space with ``observation``, ``achieved_goal`` and ``desired_goal``
    """
    goal = spaces.Box(-np.inf, np.inf, shape=(goal_dim,), dtype=np.float32)
    return spaces.Dict({"observation": observation, "achieved_goal": goal, "desired_goal": goal})


def image_space(image_size: int) -> spaces.Box:
    """
    :param image_size: side of the square image, at least ``MIN_IMAGE_SIZE`` pixels
    :return: the uint8 channel-last image space (SB3's ``VecTransposeImage`` makes it channel-first)
    """
    if not isinstance(image_size, int) or image_size < MIN_IMAGE_SIZE:
        raise ValueError(f"image_size must be an integer >= {MIN_IMAGE_SIZE} pixels, got {image_size!r}")
    return spaces.Box(0, 255, shape=(image_size, image_size, 3), dtype=np.uint8)


def check_render_mode(render_mode: str | None, allowed: tuple[str, ...]) -> None:
    """
    :param render_mode: the requested render mode
    :param allowed: the render modes the task supports
    """
    if render_mode is not None and render_mode not in allowed:
        raise ValueError(f"render_mode must be one of {allowed} or None, got {render_mode!r}")


class ImageRenderer:
    """
    Square off-screen RGB frames of a MuJoCo model, the image observations of the image tasks.

    It owns its OpenGL context and makes it current for every frame and before freeing its GPU objects.
    Neither gymnasium's ``MujocoRenderer`` (draws into whichever context was created last) nor
    ``mujoco.Renderer`` (frees its ``MjrContext`` after its GL context, deleting the objects of whichever
    context is current) is safe with several environments in one process.

    :param model: the MuJoCo model (its off-screen buffer is grown to ``size`` if needed)
    :param size: side of the image in pixels
    :param camera: name of a camera of the model, or a free camera's settings
        (``lookat``, ``distance``, ``azimuth``, ``elevation``)
    :param antialias: draw with the model's multisampling (``model.vis.quality.offsamples``, MuJoCo's default 4
        samples a pixel); False: one sample a pixel (``offsamples = 0``, set on the model), edges not smoothed, which
        software rendering (osmesa) draws several times faster
    """

    def __init__(self, model: Any, size: int, camera: str | dict[str, Any], antialias: bool = True):
        import mujoco

        self._mujoco = mujoco
        self._gl_context: Any = None
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, size)
        model.vis.global_.offheight = max(model.vis.global_.offheight, size)
        if not antialias:
            model.vis.quality.offsamples = 0  # read when the MjrContext below allocates the off-screen buffer
        try:
            from mujoco.gl_context import GLContext

            self._gl_context = GLContext(size, size)
            self._gl_context.make_current()
            self._mjr_context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        except Exception as error:  # FatalError, EGLError, AttributeError...: whatever the GL backend raises
            raise RuntimeError(f"Off-screen MuJoCo rendering is not available ({error!r}): {RENDER_FIX}.") from error
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self._mjr_context)
        self._model = model
        self._scene = mujoco.MjvScene(model, maxgeom=1000)
        self._option = mujoco.MjvOption()
        self._rect = mujoco.MjrRect(0, 0, size, size)
        self._camera = mujoco.MjvCamera()
        if isinstance(camera, str):
            self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
            self._camera.fixedcamid = model.camera(camera).id
        else:
            for key, value in camera.items():
                if isinstance(value, np.ndarray):
                    getattr(self._camera, key)[:] = value
                else:
                    setattr(self._camera, key, value)

    def render(self, data: Any) -> np.ndarray:
        """
        :param data: the ``MjData`` to draw
        :return: a uint8 image of shape (size, size, 3), rows from top to bottom
        """
        mujoco = self._mujoco
        self._gl_context.make_current()
        mujoco.mjv_updateScene(self._model, data, self._option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL, self._scene)
        mujoco.mjr_render(self._rect, self._scene, self._mjr_context)
        frame = np.empty((self._rect.height, self._rect.width, 3), dtype=np.uint8)
        mujoco.mjr_readPixels(frame, None, self._rect, self._mjr_context)
        return np.ascontiguousarray(frame[::-1])

    def close(self) -> None:
        """Free the GPU objects, then the OpenGL context."""
        if self._gl_context is None:
            return
        self._gl_context.make_current()
        self._mjr_context.free()
        self._gl_context.free()
        self._gl_context = None

    def __del__(self) -> None:
        if not sys.is_finalizing():  # at exit, the GL bindings may already be torn down
            self.close()
