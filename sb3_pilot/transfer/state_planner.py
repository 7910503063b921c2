"""
State-planner transfer across action spaces (paper section 3.3, the High-Dim-Action challenge): a target UDPO takes a
source UDPO's state planner ``h(s' | s, g)``, frozen, and learns only its own inverse dynamics.

One operation, two entry points: :func:`load_planner_from` (Python) and :class:`StatePlannerTransferCallback` (the
RL Zoo's YAML); both hand the weights to :meth:`UDPOPolicy.load_state_planner`.
"""

from __future__ import annotations

import copy
import os
import pickle
from pathlib import Path
from typing import Any, TypeVar

from gymnasium import spaces
from stable_baselines3.common.base_class import BaseAlgorithm, maybe_make_env
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.vec_env import VecEnv, VecNormalize, is_vecenv_wrapped

from sb3_pilot.common.saved_models import vecnormalize_path, without_replay_buffer
from sb3_pilot.udpo import UDPO

SelfUDPO = TypeVar("SelfUDPO", bound=UDPO)

# Set by UDPO._setup_model from the algorithm's own learning rates, and the target's own choice: never carried over
_TARGET_POLICY_KWARGS = ("planner_lr_schedule", "inverse_dynamics_lr_schedule", "freeze_state_planner")
#: Prefix of the state planner's weights in a saved UDPO policy.
_PLANNER_PREFIX = "state_planner."


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
    settings = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon", "norm_obs_keys")
    target = VecNormalize(venv, training=training, **{name: getattr(source, name) for name in settings})
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
    source: UDPO | str | os.PathLike,
    env: GymEnv | str,
    freeze: bool = True,
    source_vec_normalize: VecNormalize | str | os.PathLike | None = None,
    algorithm_class: type[SelfUDPO] = UDPO,  # type: ignore[assignment]
    **udpo_kwargs: Any,
) -> SelfUDPO:
    """
    Build a target UDPO whose state planner ``h(s' | s, g)`` is copied from a source UDPO, and whose inverse dynamics
    (and critics) start from scratch: PILoT's transfer of the decoupled policy across action spaces. The observation
    spaces must match (the planner reads the whole observation); the action spaces may differ.

    The planner's inputs stay those it was trained on: if the source used ``VecNormalize``, ``env`` is wrapped in a
    new ``VecNormalize`` carrying the source's settings and statistics (its spaces are ``env``'s), frozen
    (``training=False``) when the planner is; if it did not, ``env`` must not be normalised either.

    :param source: the source model, or the path of its saved zip
    :param env: the target env (not wrapped in ``VecNormalize``: the source decides)
    :param freeze: keep the planner (and its input statistics) unchanged while the target trains (the target policy's
        ``freeze_state_planner``)
    :param source_vec_normalize: the source's ``VecNormalize`` (or the path of its ``.save``) when ``source`` is a path
        to a model trained with it; a source model carries its own
    :param algorithm_class: the target's class (``UDPO`` or a subclass)
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
        source_model = UDPO.load(source, device="cpu", custom_objects=without_replay_buffer())
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
    policy_kwargs = {key: value for key, value in source_model.policy_kwargs.items() if key not in _TARGET_POLICY_KWARGS}
    policy_kwargs.update(udpo_kwargs.pop("policy_kwargs", None) or {})
    policy_kwargs["freeze_state_planner"] = freeze
    target = algorithm_class(policy, venv, policy_kwargs=policy_kwargs, **udpo_kwargs)
    target.policy.load_state_planner(source_model.policy.state_planner.state_dict(), source="the source model")
    return target


class StatePlannerTransferCallback(BaseCallback):
    """
    The RL Zoo's entry to :func:`load_planner_from`: when training starts, the model being trained (a UDPO) takes the
    state planner of a source UDPO saved by the zoo. Freezing is the target policy's choice, made in its YAML
    (``policy_kwargs: "dict(freeze_state_planner=True)"``)::

        callback:
          - sb3_pilot.transfer.StatePlannerTransferCallback:
              source: logs/udpo/Pilot-FetchReach-v0_1/Pilot-FetchReach-v0.zip

    The planner must see states scaled as it was trained: if the source was trained with ``normalize`` (the zoo
    saves its statistics as ``<log folder>/udpo/<env>_<id>/<env>/vecnormalize.pkl``, next to the zip), the target
    must be too, and its ``VecNormalize`` gets the source's statistics (``obs_rms`` and ``ret_rms``, deep copies;
    its spaces stay the target's), frozen (``training=False``) when the planner is; the zoo's evaluation env copies
    them from there. A source without ``normalize`` needs a target without it. Continuing a run with ``-i`` copies
    the source planner (and statistics) again.

    :param source: the source model's zip (the zoo saves it as ``<log folder>/udpo/<env>_<id>/<env>.zip``)
    :param source_vec_normalize: the source's ``vecnormalize.pkl``, if not where the zoo saves it next to ``source``
    :param verbose: 1 prints what was copied
    """

    def __init__(self, source: str, source_vec_normalize: str | None = None, verbose: int = 0):
        super().__init__(verbose)
        self.source = source
        self.source_vec_normalize = source_vec_normalize

    def _source_stats(self) -> Path | None:
        """The source's saved ``VecNormalize`` (None: it was trained without ``normalize``)."""
        if self.source_vec_normalize is not None:
            if not Path(self.source_vec_normalize).is_file():
                raise FileNotFoundError(f"source_vec_normalize {self.source_vec_normalize} is no file.")
            return Path(self.source_vec_normalize)
        stats = vecnormalize_path(self.source)  # where the zoo saves them
        return stats if stats.is_file() else None

    def _on_training_start(self) -> None:
        if not isinstance(self.model, UDPO):
            raise ValueError(f"{type(self).__name__} needs a UDPO model (it holds a state planner), got {type(self.model)}.")
        source_stats, target_norm = self._source_stats(), self.model.get_vec_normalize_env()
        if (source_stats is None) != (target_norm is None):
            used, unused = ("source", "target") if source_stats is not None else ("target", "source")
            raise ValueError(
                f"{type(self).__name__}: the {used} uses VecNormalize (`normalize`) and the {unused} does not, so the "
                "transferred planner would see states scaled otherwise than it was trained on: train both with "
                "`normalize` (the source's statistics are then carried over) or both without."
            )
        # The policy's weights only: loading the whole source model would need its env (HER's buffer)
        data, params, _ = load_from_zip_file(Path(self.source), device=self.model.device)
        mismatch = observation_space_mismatch(data["observation_space"], self.model.observation_space)
        if mismatch is not None:
            raise ValueError(f"The source's state planner ({self.source}) cannot read the target's observations: {mismatch}.")
        state_dict = {
            name[len(_PLANNER_PREFIX) :]: value for name, value in params["policy"].items() if name.startswith(_PLANNER_PREFIX)
        }
        frozen = self.model.policy.freeze_state_planner
        if source_stats is not None and target_norm is not None:
            copy_normalization_statistics(load_vec_normalize(source_stats), target_norm, training=not frozen)
        self.model.policy.load_state_planner(state_dict, source=self.source)
        if self.verbose > 0:
            stats = f", VecNormalize statistics from {source_stats}" if source_stats is not None else ""
            print(f"State planner copied from {self.source} ({'frozen' if frozen else 'trainable'}){stats}")

    def _on_step(self) -> bool:
        return True
