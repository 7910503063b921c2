"""The reward bonus of PILoT's transfer stage (paper section 3.3, eq. "bonus") and the HER buffer it needs."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np
import torch as th

from sb3_pilot.common.buffers import LeanHerReplayBuffer
from sb3_pilot.common.utils import check_number
from sb3_pilot.distill import GoalPlanner

#: Info key holding the achieved goal before the transition (``phi(s)``), which the bonus needs.
PREVIOUS_ACHIEVED_GOAL = "previous_achieved_goal"
#: Similarities of :class:`PilotBonusWrapper`.
SIMILARITIES = ("goal_cosine", "displacement_cosine", "planned_progress")


def cosine_similarity(first: np.ndarray, second: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    """Cosine of vectors along the last axis; 0 where one of them is (nearly) zero."""
    norms = np.linalg.norm(first, axis=-1) * np.linalg.norm(second, axis=-1)
    return np.sum(first * second, axis=-1) / np.maximum(norms, eps)


def planned_progress(move: np.ndarray, planned_move: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    """
    The part of ``move`` along ``planned_move``, as a fraction of ``planned_move``, clipped to [-1, 1]
    (last axis); 0 where ``planned_move`` is (nearly) zero.

    :param move: achieved moves ``phi(s') - phi(s)``, shape (..., goal_dim)
    :param planned_move: planned moves ``g_hat' - phi(s)``, same shape
    :param eps: squared length under which a planned move counts as zero
    :return: shape (...)
    """
    squared_norm = np.sum(planned_move * planned_move, axis=-1)
    progress = np.sum(move * planned_move, axis=-1) / np.maximum(squared_norm, eps)
    return np.clip(np.where(squared_norm > eps, progress, 0.0), -1.0, 1.0)


def _previous_achieved_goal(info: Any) -> np.ndarray:
    """The ``previous_achieved_goal`` of one info dict, of a batched info dict, or of a sequence of info dicts."""
    if isinstance(info, dict) and PREVIOUS_ACHIEVED_GOAL in info:
        return np.asarray(info[PREVIOUS_ACHIEVED_GOAL])
    if isinstance(info, (Sequence, np.ndarray)) and len(info) > 0 and all(PREVIOUS_ACHIEVED_GOAL in item for item in info):
        return np.stack([item[PREVIOUS_ACHIEVED_GOAL] for item in info])
    raise ValueError(
        "PilotBonusWrapper.compute_reward needs the achieved goal before each transition, in "
        f"info['{PREVIOUS_ACHIEVED_GOAL}']. With HER, use replay_buffer_class=sb3_pilot.PilotHerReplayBuffer: "
        "SB3's HerReplayBuffer does not pass it, and relabelled transitions would get a wrong bonus."
    )


class PilotBonusWrapper(gym.RewardWrapper):
    """
    Adds PILoT's bonus to the sparse reward (paper eq. "bonus"): ``r + beta * similarity(phi(s'), g_hat')`` with the
    immediate landmark ``g_hat' = f(phi(s), g_target)`` of a distilled :class:`~sb3_pilot.GoalPlanner`
    (its mean, so the reward of a transition is a function of it, as HER needs).

    Similarities:

    - ``"goal_cosine"``: the paper's, cosine of the goal vectors ``phi(s')`` and ``g_hat'``. It depends on where the
      origin of the goal space lies: with the origin inside the workspace, it rewards being on the landmark's side
      of the origin rather than moving towards it.
    - ``"displacement_cosine"``: cosine of the achieved move ``phi(s') - phi(s)`` and the planned one
      ``g_hat' - phi(s)``; origin-free, and 0 when the agent does not move. It rewards the direction of a move, not its
      length, so slow moves towards the landmark and fast moves back earn a bonus over a cycle.
    - ``"planned_progress"``: how far the agent advances along the planned move, as a fraction of it:
      ``<phi(s') - phi(s), g_hat' - phi(s)> / ||g_hat' - phi(s)||^2``, clipped to [-1, 1]; origin-free, and moving
      back costs what moving forward earned.

    ``compute_reward(achieved_goal, desired_goal, info)`` gives the sparse reward plus the bonus *for that desired
    goal*, batched, so transitions relabelled by HER get the bonus of their new goal. It reads ``phi(s)`` from
    ``info["previous_achieved_goal"]``, which every step's info holds and which :class:`PilotHerReplayBuffer` passes
    from the stored observations; SB3's ``HerReplayBuffer`` does not, and then ``compute_reward`` raises an error.

    In an RL-Zoo YAML: ``env_wrapper: [{sb3_pilot.PilotBonusWrapper: {planner: path/to/planner.pt, beta: 1.0}}]``.

    :param env: a goal env (Dict observation with ``achieved_goal`` and ``desired_goal``)
    :param planner: the distilled goal planner, or the path of its file (:meth:`GoalPlanner.save`); its goal size and
        source task are checked against ``env``. When the source task's goals are the env's in other coordinates
        (:func:`~sb3_pilot.share_goal_space` with a ``goal_map``), the env's goals are mapped into the planner's
        coordinates and the landmark back: the bonus, also of HER's relabelled goals, is in the env's coordinates
    :param beta: bonus ratio ``beta``
    :param similarity: ``"displacement_cosine"``, ``"goal_cosine"`` or ``"planned_progress"``
    """

    def __init__(
        self,
        env: gym.Env,
        planner: GoalPlanner | str | os.PathLike,
        beta: float = 1.0,
        similarity: str = "displacement_cosine",
    ):
        check_number("beta", beta, minimum=0)
        if similarity not in SIMILARITIES:
            raise ValueError(f"Unknown similarity {similarity!r}, choose one of {SIMILARITIES}.")
        super().__init__(env)
        self.planner, self.goal_map = GoalPlanner.for_env(planner, env)
        self.beta = beta
        self.similarity = similarity
        self._achieved_goal: np.ndarray | None = None
        self._transition: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    def bonus(self, previous_achieved_goal: np.ndarray, achieved_goal: np.ndarray, desired_goal: np.ndarray) -> np.ndarray:
        """
        The bonus ``similarity(phi(s'), g_hat')``, without ``beta``.

        :param previous_achieved_goal: ``phi(s)``, shape (goal_dim,) or (n, goal_dim)
        :param achieved_goal: ``phi(s')``, same shape
        :param desired_goal: ``g_target``, same shape
        :return: float32 array of shape () or (n,)
        """
        if self.goal_map is None:
            landmark = self.planner.predict(previous_achieved_goal, desired_goal)
        else:  # the planner plans in its source task's coordinates
            landmark = self.goal_map.through(self.planner.predict, previous_achieved_goal, desired_goal)
        if self.similarity == "goal_cosine":
            return cosine_similarity(achieved_goal, landmark).astype(np.float32)
        move, planned_move = achieved_goal - previous_achieved_goal, landmark - previous_achieved_goal
        if self.similarity == "planned_progress":
            return planned_progress(move, planned_move).astype(np.float32)
        return cosine_similarity(move, planned_move).astype(np.float32)

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """
        Sparse reward of the wrapped env plus ``beta`` times the bonus for ``desired_goal`` (batched).

        :param achieved_goal: ``phi(s')``, shape (goal_dim,) or (n, goal_dim)
        :param desired_goal: goals to reward, same shape
        :param info: holds ``previous_achieved_goal`` (``phi(s)``): one info dict, a batched one, or one per goal
        """
        previous = _previous_achieved_goal(info)
        if previous.shape != np.shape(achieved_goal):
            raise ValueError(f"previous_achieved_goal has shape {previous.shape}, achieved_goal {np.shape(achieved_goal)}.")
        sparse = self.env.get_wrapper_attr("compute_reward")(achieved_goal, desired_goal, info)
        return sparse + self.beta * self.bonus(previous, np.asarray(achieved_goal), np.asarray(desired_goal))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        self._achieved_goal = np.array(observation["achieved_goal"])
        return observation, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        if self._achieved_goal is None:
            raise RuntimeError("Call reset() before step().")
        observation, reward, terminated, truncated, info = self.env.step(action)
        self._transition = (self._achieved_goal, observation["achieved_goal"], observation["desired_goal"])
        info[PREVIOUS_ACHIEVED_GOAL] = self._achieved_goal
        self._achieved_goal = np.array(observation["achieved_goal"])
        return observation, self.reward(reward), terminated, truncated, info

    def reward(self, reward: SupportsFloat) -> float:
        """The env's reward plus ``beta`` times the bonus of the last transition."""
        assert self._transition is not None
        return float(reward) + self.beta * float(self.bonus(*self._transition))


class _StoredPreviousAchievedGoals:
    """
    Stands in for ``HerReplayBuffer.infos``: reading it at ``(batch_indices, env_indices)`` gives the info
    :meth:`PilotBonusWrapper.compute_reward` needs, ``{"previous_achieved_goal": achieved goals stored with those
    transitions}``, one array (cheap to deep-copy; a host copy where the buffer stores tensors on a device). Writes are
    ignored: no info dict is stored.
    """

    def __init__(self, buffer: LeanHerReplayBuffer):
        self.buffer = buffer

    def __getitem__(self, index: Any) -> dict[str, np.ndarray]:
        goals = self.buffer.observations["achieved_goal"][index]
        return {PREVIOUS_ACHIEVED_GOAL: goals.cpu().numpy() if isinstance(goals, th.Tensor) else goals}

    def __setitem__(self, index: Any, value: Any) -> None:
        pass


class PilotHerReplayBuffer(LeanHerReplayBuffer):
    """
    ``HerReplayBuffer`` for envs wrapped in :class:`PilotBonusWrapper`: when it relabels a transition ``s -> s'``,
    ``compute_reward`` receives ``info = {"previous_achieved_goal": phi(s)}`` (a batch), read from the stored
    observations, so the bonus is that of the new goal. No info dict is stored or deep-copied, unlike
    ``copy_info_dict=True`` (which costs training throughput).

    Same parameters as ``HerReplayBuffer``, except ``copy_info_dict``, and :class:`LeanHerReplayBuffer`'s ``storage``
    (``"device"``: the bonus of relabelled goals is computed on host copies of their goals).
    """

    def __init__(self, *args: Any, **kwargs: Any):
        if "copy_info_dict" in kwargs:
            raise ValueError("PilotHerReplayBuffer passes the previous achieved goal itself: do not set copy_info_dict.")
        super().__init__(*args, copy_info_dict=True, **kwargs)
        self.infos = _StoredPreviousAchievedGoals(self)  # type: ignore[assignment]

    def __getstate__(self) -> dict[str, Any]:
        # the stand-in reads this buffer: pickled apart from it (a checkpoint's state), it would carry a copy of the
        # whole buffer, frames included, and read that copy once loaded
        state = super().__getstate__()
        state.pop("infos", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        super().__setstate__({key: value for key, value in state.items() if key != "infos"})
        self.infos = _StoredPreviousAchievedGoals(self)  # type: ignore[assignment]
