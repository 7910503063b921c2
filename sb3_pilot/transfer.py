"""State-planner transfer across action spaces (paper section 3.3, the High-Dim-Action challenge)."""

from __future__ import annotations

import copy
import os
import pickle
from typing import Any, TypeVar

from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm, maybe_make_env
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.vec_env import VecEnv, VecNormalize, is_vecenv_wrapped

from sb3_pilot.udpo import UDPO

SelfUDPO = TypeVar("SelfUDPO", bound=UDPO)

# Set by UDPO._setup_model from the algorithm's own learning rates: never carried over
_LR_SCHEDULE_KWARGS = ("planner_lr_schedule", "inverse_dynamics_lr_schedule")


def observation_space_mismatch(source: spaces.Space, target: spaces.Space) -> str | None:
    """
    :return: what differs between two observation spaces in what the state planner reads (keys and shapes),
        or None if nothing does
    """
    if isinstance(source, spaces.Dict) != isinstance(target, spaces.Dict):
        return f"one is a Dict and the other is not ({source} vs {target})"
    if isinstance(source, spaces.Dict) and isinstance(target, spaces.Dict):
        if set(source.spaces) != set(target.spaces):
            return f"keys {sorted(source.spaces)} vs {sorted(target.spaces)}"
        for key in source.spaces:
            if source[key].shape != target[key].shape:
                return f"'{key}' has shape {source[key].shape} vs {target[key].shape}"
        return None
    return None if source.shape == target.shape else f"shape {source.shape} vs {target.shape}"


def load_vec_normalize(source_vec_normalize: VecNormalize | str | os.PathLike) -> VecNormalize:
    """The source's ``VecNormalize`` (statistics only: a path is unpickled without attaching a venv)."""
    if isinstance(source_vec_normalize, VecNormalize):
        return source_vec_normalize
    with open(source_vec_normalize, "rb") as file_handler:
        vec_normalize = pickle.load(file_handler)
    if not isinstance(vec_normalize, VecNormalize):
        raise ValueError(f"{source_vec_normalize} does not hold a VecNormalize (saved with VecNormalize.save).")
    return vec_normalize


def _normalize_like(venv: VecEnv, source: VecNormalize, training: bool) -> VecNormalize:
    """
    Wrap ``venv`` in a new ``VecNormalize`` with the settings and statistics of ``source``. (``VecNormalize.load``
    would keep the saved spaces, among them the source's action space.)
    """
    target = VecNormalize(
        venv,
        training=training,
        norm_obs=source.norm_obs,
        norm_reward=source.norm_reward,
        clip_obs=source.clip_obs,
        clip_reward=source.clip_reward,
        gamma=source.gamma,
        epsilon=source.epsilon,
        norm_obs_keys=source.norm_obs_keys,
    )
    copy_normalization_statistics(source, target, training=training)
    return target


def _rms_shapes(obs_rms: Any) -> Any:
    """Shapes of a ``VecNormalize.obs_rms`` (one running statistic, or one per key of a Dict observation)."""
    if isinstance(obs_rms, dict):
        return {key: tuple(stats.mean.shape) for key, stats in obs_rms.items()}
    return tuple(obs_rms.mean.shape)


def copy_normalization_statistics(source: VecNormalize, target: VecNormalize, training: bool) -> None:
    """
    Copy the running statistics of ``source`` (``obs_rms``, ``ret_rms``: deep copies) into ``target``, whose venv
    and spaces stay its own, so that a transferred state planner sees states scaled as on the source.

    :param source: the source's ``VecNormalize`` (e.g. unpickled without a venv)
    :param target: the target's ``VecNormalize``
    :param training: whether ``target`` keeps updating the statistics (False: frozen at the source's)
    :raises ValueError: if the two normalise observations differently (``norm_obs``, ``norm_obs_keys``,
        ``clip_obs``, ``epsilon``) or their statistics have other shapes
    """
    for setting in ("norm_obs", "norm_obs_keys", "clip_obs", "epsilon"):
        source_value, target_value = getattr(source, setting), getattr(target, setting)
        if setting == "norm_obs_keys" and source_value is not None and target_value is not None:
            source_value, target_value = sorted(source_value), sorted(target_value)
        if source_value != target_value:
            raise ValueError(
                f"The source's and the target's VecNormalize differ in {setting} ({source_value!r} vs "
                f"{target_value!r}): the planner would see observations scaled otherwise."
            )
    if source.norm_obs and _rms_shapes(source.obs_rms) != _rms_shapes(target.obs_rms):
        raise ValueError(
            "The source's observation statistics do not fit the target's observations: "
            f"{_rms_shapes(source.obs_rms)} vs {_rms_shapes(target.obs_rms)}."
        )
    target.obs_rms = copy.deepcopy(source.obs_rms)
    target.ret_rms = copy.deepcopy(source.ret_rms)
    target.training = training


def load_planner_from(
    algorithm_class: type[SelfUDPO],
    source: UDPO | str | os.PathLike,
    env: GymEnv | str,
    freeze: bool = True,
    source_vec_normalize: VecNormalize | str | os.PathLike | None = None,
    **udpo_kwargs: Any,
) -> SelfUDPO:
    """
    Build a target UDPO whose state planner ``h(s' | s, g)`` is copied from a source UDPO, and whose inverse dynamics
    (and critics) start from scratch: PILoT's transfer of the decoupled policy across action spaces. The observation
    spaces must match (the planner reads the whole observation); the action spaces may differ.

    The planner's inputs stay those it was trained on: if the source used ``VecNormalize``, ``env`` is wrapped in a
    new ``VecNormalize`` carrying the source's settings and statistics (its spaces are ``env``'s), frozen
    (``training=False``) when the planner is; if it did not, ``env`` must not be normalised either.

    :param algorithm_class: the target's class (``UDPO`` or a subclass)
    :param source: the source model, or the path of its saved zip
    :param env: the target env (not wrapped in ``VecNormalize``: the source decides)
    :param freeze: keep the planner (and its input statistics) unchanged while the target trains
    :param source_vec_normalize: the source's ``VecNormalize`` (or the path of its ``.save``) when ``source`` is a path
        to a model trained with it; a source model carries its own
    :param udpo_kwargs: arguments of the target (``policy`` defaults to the source's; ``policy_kwargs`` are merged
        over the source's, and must keep the planner's architecture)
    :return: the target model
    """
    if isinstance(source, BaseAlgorithm):
        if not isinstance(source, UDPO):
            raise ValueError(f"The source must be a UDPO model (it holds the state planner), got {type(source).__name__}.")
        if source_vec_normalize is not None:
            raise ValueError("source_vec_normalize is for a source given as a path: a source model carries its own.")
        source_model, source_norm = source, source.get_vec_normalize_env()
    else:
        # Only the policy is needed: no replay buffer (a HER buffer could not be built without the source's env)
        no_buffer = {"replay_buffer_class": None, "replay_buffer_kwargs": {}, "buffer_size": 1}
        source_model = algorithm_class.load(source, device="cpu", custom_objects=no_buffer)
        source_norm = None if source_vec_normalize is None else load_vec_normalize(source_vec_normalize)

    venv = BaseAlgorithm._wrap_env(maybe_make_env(env, verbose=0))
    if is_vecenv_wrapped(venv, VecNormalize):
        raise ValueError(
            "Pass the target env without VecNormalize: the transferred planner must see states scaled as in the source, "
            "so load_planner_from adds the source's VecNormalize (if it had one) itself."
        )
    mismatch = observation_space_mismatch(source_model.observation_space, venv.observation_space)
    if mismatch is not None:
        raise ValueError(f"The source's state planner cannot read the target's observations: {mismatch}.")
    if source_norm is not None:
        venv = _normalize_like(venv, source_norm, training=not freeze)

    policy = udpo_kwargs.pop("policy", source_model.policy_class)
    policy_kwargs = {key: value for key, value in source_model.policy_kwargs.items() if key not in _LR_SCHEDULE_KWARGS}
    policy_kwargs.update(udpo_kwargs.pop("policy_kwargs", None) or {})
    target = algorithm_class(policy, venv, policy_kwargs=policy_kwargs, **udpo_kwargs)

    source_planner, target_planner = source_model.policy.state_planner, target.policy.state_planner
    if source_planner.state_dim != target_planner.state_dim:
        raise ValueError(f"Planner-state sizes differ: source {source_planner.state_dim}, target {target_planner.state_dim}.")
    source_shapes = {name: tuple(value.shape) for name, value in source_planner.state_dict().items()}
    target_shapes = {name: tuple(value.shape) for name, value in target_planner.state_dict().items()}
    if source_shapes != target_shapes:
        raise ValueError(
            "The target's state planner has another architecture than the source's: keep the source's net_arch / "
            f"features extractor in policy_kwargs (source {source_shapes}, target {target_shapes})."
        )
    target_planner.load_state_dict(source_planner.state_dict())
    if freeze:
        target.freeze_planner = True
        target_planner.requires_grad_(False)
    return target
