"""
Features extractors for the transfer targets, selectable from an RL-Zoo YAML's ``policy_kwargs``:
:class:`GoalRelativeExtractor`, translation- and heading-invariant features for a goal-conditioned controller (the
zero-shot Ant-Maze controller), which then acts the same anywhere in a larger map.

The pixel-only agents' encoder and policy live in :mod:`sb3_pilot.pixels`; their names stay importable from here,
where the YAML entries under ``hyperparams/`` and models saved before the move name them.
"""

from __future__ import annotations

import gymnasium as gym
import torch as th
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

from sb3_pilot.pixels import EncodedObservations, PixelGoalExtractor, PixelGoalSACPolicy, RandomShift

#: with the pixel agents' classes, importable from their former module (YAML entries, saved models)
__all__ = [
    "EncodedObservations",
    "GoalRelativeExtractor",
    "PixelGoalExtractor",
    "PixelGoalSACPolicy",
    "RandomShift",
    "quaternion_yaw",
    "remove_yaw",
    "rotate_xy",
]


def quaternion_yaw(quaternion: th.Tensor) -> th.Tensor:
    """
    :param quaternion: ``(..., 4)`` unit quaternions ``w, x, y, z`` (MuJoCo's order)
    :return: ``(...)`` yaw (rotation about the world z axis) of the body's x axis, in radians
    """
    w, x, y, z = quaternion.unbind(-1)
    return th.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def remove_yaw(quaternion: th.Tensor, yaw: th.Tensor) -> th.Tensor:
    """
    :param quaternion: ``(..., 4)`` quaternions ``w, x, y, z``
    :param yaw: ``(...)`` yaw angles
    :return: ``q_yaw^-1 * quaternion``: the same orientation seen from a frame turned by ``yaw`` about z
    """
    w, x, y, z = quaternion.unbind(-1)
    c, s = th.cos(yaw / 2), th.sin(yaw / 2)  # q_yaw^-1 = (c, 0, 0, -s)
    return th.stack((c * w + s * z, c * x + s * y, c * y - s * x, c * z - s * w), dim=-1)


def rotate_xy(vector: th.Tensor, angle: th.Tensor) -> th.Tensor:
    """
    :param vector: ``(..., 2)`` vectors
    :param angle: ``(...)`` angles
    :return: the vectors rotated by ``angle`` (counter-clockwise)
    """
    c, s = th.cos(angle), th.sin(angle)
    x, y = vector.unbind(-1)
    return th.stack((c * x - s * y, s * x + c * y), dim=-1)


class GoalRelativeExtractor(BaseFeaturesExtractor):
    """
    Translation-invariant features of a goal-conditioned ``Dict`` observation (``observation``, ``achieved_goal``,
    ``desired_goal``), where ``observation`` starts with the absolute position (``position_dim`` entries, the
    achieved goal's coordinates).

    Features: ``observation`` without its position, then the goal seen from the achieved goal,
    ``desired_goal - achieved_goal``, as its direction (unit vector) and its length clipped to
    ``max_goal_distance`` (a farther goal looks like one at that distance: what to do is walk towards it).

    With ``quaternion_index`` (planar goals of a free-floating torso, e.g. the Ant: 3, after x, y, z), everything
    is also turned into the torso's heading frame: the goal direction and the ``velocity_index`` xy velocity
    (world frame in MuJoCo's ``qvel``) are rotated by minus the torso's yaw and the torso's quaternion loses its
    yaw. The features are then the same for any position and heading of the same posture and motion.

    :param observation_space: the ``Dict`` observation space
    :param position_dim: number of leading ``observation`` entries holding the absolute position
    :param max_goal_distance: the goal's distance is clipped to it (None: not clipped)
    :param quaternion_index: index in ``observation`` of the torso's quaternion ``w, x, y, z`` (None: no
        heading frame; the Ant's is 3)
    :param velocity_index: index in ``observation`` of the torso's world-frame linear velocity (its x, y are
        rotated into the heading frame; the Ant's is 15)
    """

    def __init__(
        self,
        observation_space: gym.spaces.Dict,
        position_dim: int = 2,
        max_goal_distance: float | None = 3.0,
        quaternion_index: int | None = 3,
        velocity_index: int | None = 15,
    ):
        if not isinstance(observation_space, gym.spaces.Dict) or not {"observation", "achieved_goal", "desired_goal"} <= set(
            observation_space.spaces
        ):
            raise ValueError(
                f"GoalRelativeExtractor needs a goal-conditioned Dict observation space, got {observation_space}."
            )
        obs_dim = observation_space["observation"].shape[0]
        goal_dim = observation_space["desired_goal"].shape[0]
        if position_dim > obs_dim:
            raise ValueError(f"position_dim {position_dim} exceeds the observation size {obs_dim}.")
        if quaternion_index is not None:
            if goal_dim != 2:
                raise ValueError(f"The heading frame needs planar (2-dim) goals, got {goal_dim}-dim goals.")
            if quaternion_index < position_dim or quaternion_index + 4 > obs_dim:
                raise ValueError(f"quaternion_index {quaternion_index} does not fit the observation (size {obs_dim}).")
            if velocity_index is not None and (velocity_index < position_dim or velocity_index + 2 > obs_dim):
                raise ValueError(f"velocity_index {velocity_index} does not fit the observation (size {obs_dim}).")
        super().__init__(observation_space, features_dim=obs_dim - position_dim + goal_dim + 1)
        self.position_dim = position_dim
        self.max_goal_distance = max_goal_distance
        self.quaternion_index = quaternion_index
        self.velocity_index = velocity_index

    def forward(self, observations: dict[str, th.Tensor]) -> th.Tensor:
        observation = observations["observation"].float()
        delta = observations["desired_goal"].float() - observations["achieved_goal"].float()
        if self.quaternion_index is not None:
            observation = observation.clone()
            q_slice = slice(self.quaternion_index, self.quaternion_index + 4)
            yaw = quaternion_yaw(observation[:, q_slice])
            observation[:, q_slice] = remove_yaw(observation[:, q_slice], yaw)
            if self.velocity_index is not None:
                v_slice = slice(self.velocity_index, self.velocity_index + 2)
                observation[:, v_slice] = rotate_xy(observation[:, v_slice], -yaw)
            delta = rotate_xy(delta, -yaw)
        distance = th.linalg.vector_norm(delta, dim=-1, keepdim=True)
        direction = delta / distance.clamp_min(1e-6)
        if self.max_goal_distance is not None:
            distance = distance.clamp_max(self.max_goal_distance)
        return th.cat((observation[:, self.position_dim :], direction, distance), dim=-1)
