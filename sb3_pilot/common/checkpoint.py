"""
Resumable training of an off-policy model (SAC, LeanSAC, UDPO, TD3, ...): a checkpoint that a later process continues
from where the first stopped, the networks, the optimizers' state, the temperature, the counters and the replay
buffer included. A checkpoint folder holds:

- ``checkpoint.json``: the env steps it was taken at, the run's settings (a checkpoint of another task or other
  settings is refused, naming what differs), its files and, where the caller gives it, ``training_s``: the wall time
  training took to reach it, summed over the processes that led to it (:class:`CheckpointEvery`). Written last, by a
  rename: a process stopped while saving leaves the previous checkpoint whole;
- ``<steps>/model.zip``: the model as ``model.save`` writes it; ``<steps>/state.pkl``: the random generators (torch,
  numpy, Python), the ``VecNormalize`` statistics and the replay buffer's bookkeeping; ``<steps>/replay_buffer.npz``:
  the buffer's arrays but its frames, compressed;
- ``frames/``: the buffer's frames (its uint8 image observations), compressed (``np.savez_compressed``) in chunks of
  rows, each chunk written once: a checkpoint writes the rows added since the previous one (all of them once the
  buffer has wrapped around). A next frame that is the following row's frame (within an episode, always) is stored
  once.

A resumed model starts a new episode (the env's state is not saved), its env seeded anew from the run's seed and the
checkpoint's env steps (so that its episodes do not repeat the run's first ones): a HER buffer's interrupted episode
is truncated there (SB3's ``truncate_last_trajectory``), and the counters (env steps, gradient steps, episodes) go on
from the checkpoint's. Continue it with ``model.learn(total - model.num_timesteps, reset_num_timesteps=False)``, or, where the
caller's ``learn`` resets the counters (the RL Zoo's), with :class:`RestoreCounters` among the callbacks.
"""

from __future__ import annotations

import json
import os
import pickle
import random
import shutil
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from stable_baselines3.common.buffers import ReplayBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.her.her_replay_buffer import HerReplayBuffer

#: The file that makes a folder a checkpoint (see the module's doc).
CHECKPOINT_FILE = "checkpoint.json"
#: The format of the files, refused if another.
FORMAT = 1
#: The replay buffer's observation entries, whose frames are stored in chunks.
_OBSERVATION_KEYS = ("observations", "next_observations")


def _json(value: Any) -> Any:
    """``value`` as JSON reads it back (tuples as lists, other objects by their ``repr``)."""
    return json.loads(json.dumps(value, default=repr))


def _buffer_state(buffer: ReplayBuffer) -> dict[str, Any]:
    """A shallow copy of what pickling the buffer saves (its arrays as numpy arrays, no env)."""
    return dict(buffer.__getstate__())


def _set_buffer_state(buffer: ReplayBuffer, state: dict[str, Any]) -> None:
    setstate = getattr(buffer, "__setstate__", None)
    if setstate is not None:
        setstate(state)
    else:
        buffer.__dict__.update(state)


def _split_buffer(state: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, Any]]:
    """
    The buffer's state as frames (uint8 arrays of images, by ``entry/key``), other per-row arrays (numbers) and the
    rest (scalars, the per-row info dicts), its per-row arrays cut to the rows written.
    """
    size, rows = state["buffer_size"], state["buffer_size"] if state["full"] else state["pos"]
    frames: dict[str, np.ndarray] = {}
    arrays: dict[str, np.ndarray] = {}
    rest: dict[str, Any] = {}
    entries: list[tuple[str, Any]] = []
    for key, value in state.items():
        if key in _OBSERVATION_KEYS and isinstance(value, dict):
            entries += [(f"{key}/{name}", array) for name, array in value.items()]
        else:
            entries.append((key, value))
    for name, value in entries:
        if not isinstance(value, np.ndarray) or value.shape[:1] != (size,):
            rest[name] = value
        elif value.dtype == np.uint8 and value.ndim >= 4 and name.split("/")[0] in _OBSERVATION_KEYS:
            frames[name] = value[:rows]
        elif value.dtype == object:
            rest[name] = value[:rows]
        else:
            arrays[name] = value[:rows]
    return frames, arrays, rest


def _entry(state: dict[str, Any], name: str) -> Any:
    """The buffer state's array of ``name`` (``entry/key`` for an observation dict's)."""
    key, _, sub = name.partition("/")
    return state[key][sub] if sub else state[key]


def _save_frame_chunk(path: Path, frames: dict[str, np.ndarray], start: int, end: int) -> None:
    """Rows ``start:end`` of the frames, a next frame that is the following row's frame stored once."""
    data: dict[str, np.ndarray] = {}
    for name, array in frames.items():
        rows = array[start:end]
        key = name.replace("/", ".")
        partner = frames.get(name.replace("next_observations/", "observations/", 1))
        if name.startswith("next_observations/") and partner is not None and partner.shape == array.shape:
            following = partner[start + 1 : end]
            same = np.zeros(rows.shape[:2], dtype=bool)
            same[:-1] = (rows[:-1] == following).all(axis=tuple(range(2, rows.ndim)))  # a one-row chunk: none
            data[f"{key}.same"], data[f"{key}.other"] = same, rows[~same]
        else:
            data[key] = rows
    temporary = path.with_suffix(".tmp.npz")
    np.savez_compressed(temporary, **data)
    os.replace(temporary, path)


def _load_frame_chunk(path: Path, state: dict[str, Any], names: Sequence[str], start: int, end: int) -> None:
    """Write a chunk's rows into the buffer state's frame arrays (:func:`_save_frame_chunk`'s inverse)."""
    with np.load(path) as data:
        for name in sorted(names, key=lambda name: name.startswith("next_observations/")):  # observations first
            key, target = name.replace("/", "."), _entry(state, name)[start:end]
            if key in data:
                target[...] = data[key]
                continue
            same = data[f"{key}.same"]
            target[~same] = data[f"{key}.other"]
            following = _entry(state, name.replace("next_observations/", "observations/", 1))[start + 1 : end]
            target[:-1][same[:-1]] = following[same[:-1]]


def read_checkpoint(folder: str | os.PathLike) -> dict[str, Any]:
    """
    :param folder: a checkpoint folder
    :return: its ``checkpoint.json``
    :raise FileNotFoundError: if the folder holds no checkpoint (naming it)
    :raise ValueError: for a checkpoint of another format
    """
    path = Path(folder) / CHECKPOINT_FILE
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint in {folder} (no {CHECKPOINT_FILE}): nothing to resume")
    info = json.loads(path.read_text())
    if info.get("format") != FORMAT:
        raise ValueError(f"{path} is a checkpoint of format {info.get('format')!r}, this package reads {FORMAT}")
    return info


def check_settings(info: dict[str, Any], settings: dict[str, Any], folder: str | os.PathLike) -> None:
    """
    :param info: a checkpoint's :func:`read_checkpoint`
    :param settings: the settings of the run that would resume from it
    :param folder: the checkpoint's folder (for the message)
    :raise ValueError: naming each setting that differs, with both values
    """
    recorded, current = info["settings"], _json(settings)
    differ = [key for key in sorted(set(recorded) | set(current)) if recorded.get(key) != current.get(key)]
    details: list[str] = []
    for key in differ:
        old, new = recorded.get(key), current.get(key)
        if isinstance(old, dict) and isinstance(new, dict):
            details += [
                f"{key}.{sub}: {old.get(sub)!r} in the checkpoint, {new.get(sub)!r} now"
                for sub in sorted(set(old) | set(new))
                if old.get(sub) != new.get(sub)
            ]
        else:
            details.append(f"{key}: {old!r} in the checkpoint, {new!r} now")
    if details:
        raise ValueError(
            f"the checkpoint in {folder} is of another run ({'; '.join(details)}): resume it with its own settings, "
            "or train the new ones in another folder"
        )


def save_checkpoint(
    model: OffPolicyAlgorithm, folder: str | os.PathLike, settings: dict[str, Any], training_s: float | None = None
) -> Path:
    """
    Save a checkpoint of ``model`` in ``folder`` (see the module's doc), replacing the previous one there, whose frame
    chunks it reuses where the buffer has not wrapped around since.

    :param model: the model (with its replay buffer)
    :param folder: the checkpoint folder (created if needed)
    :param settings: what identifies the run (JSON-able; e.g. task, algorithm, hyperparameters, seed), checked on resume
    :param training_s: the wall time training took to reach this checkpoint, recorded as ``training_s``; None: not
        recorded
    :return: the folder of this checkpoint's model (``folder/<steps>``)
    """
    folder = Path(folder)
    (folder / "frames").mkdir(parents=True, exist_ok=True)
    previous = read_checkpoint(folder) if (folder / CHECKPOINT_FILE).is_file() else None
    steps = model.num_timesteps
    step_folder = folder / str(steps)
    if step_folder.exists():
        shutil.rmtree(step_folder)
    step_folder.mkdir()
    model.save(step_folder / "model.zip")
    buffer = model.replay_buffer
    assert buffer is not None, "the model has no replay buffer"
    frames, arrays, rest = _split_buffer(_buffer_state(buffer))
    rows = buffer.buffer_size if buffer.full else buffer.pos
    chunks: list[dict[str, Any]] = []
    start = 0
    if previous is not None and not buffer.full and previous["frame_names"] == sorted(frames):
        kept = [chunk for chunk in previous["frame_chunks"] if chunk["end"] <= rows]
        if len(kept) == len(previous["frame_chunks"]):  # no row of theirs rewritten since
            chunks, start = kept, (kept[-1]["end"] if kept else 0)
    if frames and rows > start:
        name = f"frames_{start}_{rows}_at_{steps}.npz"
        _save_frame_chunk(folder / "frames" / name, frames, start, rows)
        chunks.append({"file": name, "start": start, "end": rows})
    np.savez_compressed(step_folder / "replay_buffer.npz", **{name.replace("/", "."): a for name, a in arrays.items()})
    vec_normalize = model.get_vec_normalize_env()
    state = {
        "buffer": rest,
        "buffer_class": type(buffer).__name__,
        "rng": {"torch": th.get_rng_state(), "numpy": np.random.get_state(), "random": random.getstate()},
        "vec_normalize": None if vec_normalize is None else (vec_normalize.obs_rms, vec_normalize.ret_rms),
    }
    with open(step_folder / "state.pkl", "wb") as file:
        pickle.dump(state, file)
    info = {
        "format": FORMAT,
        "num_timesteps": steps,
        "folder": str(steps),
        "buffer_rows": rows,
        "frame_names": sorted(frames),
        "frame_chunks": chunks,
        "settings": _json(settings),
        **({} if training_s is None else {"training_s": round(training_s, 3)}),
    }
    temporary = folder / f"{CHECKPOINT_FILE}.tmp"
    temporary.write_text(json.dumps(info, indent=1) + "\n")
    os.replace(temporary, folder / CHECKPOINT_FILE)
    # what the checkpoint no longer reads
    for path in folder.iterdir():
        if path.is_dir() and path.name not in ("frames", str(steps)):
            shutil.rmtree(path)
    for path in (folder / "frames").iterdir():
        if path.name not in {chunk["file"] for chunk in chunks}:
            path.unlink()
    return step_folder


def load_checkpoint(
    folder: str | os.PathLike,
    algo_class: type[OffPolicyAlgorithm],
    env: VecEnv,
    settings: dict[str, Any],
    **load_kwargs: Any,
) -> OffPolicyAlgorithm:
    """
    The model of a checkpoint, with its replay buffer, random generators and ``VecNormalize`` statistics, ready to
    continue (its env starts a new episode; see the module's doc).

    :param folder: the checkpoint folder
    :param algo_class: the model's class (e.g. ``LeanSAC``)
    :param env: the env to continue on (its ``VecNormalize``, if any, gets the checkpoint's statistics)
    :param settings: the resuming run's settings, which must be the checkpoint's (:func:`check_settings`)
    :param load_kwargs: other arguments of ``algo_class.load`` (``device``, ``verbose``, ...)
    :raise FileNotFoundError: without a checkpoint
    :raise ValueError: for a checkpoint of other settings, or one whose buffer does not fit the model's
    """
    info = read_checkpoint(folder)
    check_settings(info, settings, folder)
    folder = Path(folder)
    step_folder = folder / info["folder"]
    model = algo_class.load(step_folder / "model.zip", env=env, **load_kwargs)
    with open(step_folder / "state.pkl", "rb") as file:
        saved = pickle.load(file)
    buffer = model.replay_buffer
    assert buffer is not None
    if type(buffer).__name__ != saved["buffer_class"]:
        kinds = f"a {saved['buffer_class']}, the model's a {type(buffer).__name__}"
        raise ValueError(f"{folder}: the checkpoint's replay buffer is {kinds}")
    state = _buffer_state(buffer)  # the new buffer's arrays, allocated; the checkpoint's rows are written into them
    rows = info["buffer_rows"]
    with np.load(step_folder / "replay_buffer.npz") as data:
        for key in data.files:
            name = key.replace(".", "/", 1) if key.split(".")[0] in _OBSERVATION_KEYS else key
            target = _entry(state, name)
            if target.shape[1:] != data[key].shape[1:] or rows > len(target):
                shapes = f"{data[key].shape}, the model's {target.shape}"
                raise ValueError(f"{folder}: the checkpoint's {name} is of shape {shapes}")
            target[:rows] = data[key]
    for chunk in info["frame_chunks"]:
        _load_frame_chunk(folder / "frames" / chunk["file"], state, info["frame_names"], chunk["start"], chunk["end"])
    for name, value in saved["buffer"].items():
        if isinstance(value, np.ndarray) and value.dtype == object and name in state and len(state[name]) >= len(value):
            state[name][: len(value)] = value  # per-row objects (HER's infos), cut to the rows written
        elif "/" not in name:
            state[name] = value
    _set_buffer_state(buffer, state)
    buffer.device = model.device
    if isinstance(buffer, HerReplayBuffer):
        buffer.set_env(model.get_env())  # type: ignore[arg-type]
        buffer.truncate_last_trajectory()  # the interrupted episode ends where the checkpoint was taken
    rng = saved["rng"]
    th.set_rng_state(rng["torch"])
    np.random.set_state(rng["numpy"])
    random.setstate(rng["random"])
    vec_normalize = model.get_vec_normalize_env()
    if (vec_normalize is None) != (saved["vec_normalize"] is None):
        raise ValueError(f"{folder}: the checkpoint's env and this one differ in their VecNormalize")
    if vec_normalize is not None:
        vec_normalize.obs_rms, vec_normalize.ret_rms = saved["vec_normalize"]
    model._last_obs = None  # type: ignore[assignment]  # learn() resets the env: a new episode
    if model.seed is not None:
        model.get_env().seed(model.seed + model.num_timesteps)  # type: ignore[union-attr]
    return model


class CheckpointEvery(BaseCallback):
    """
    :func:`save_checkpoint` every ``save_freq`` calls (vector env steps) into ``folder``, each with the wall time
    training took to reach it (:meth:`training_s`).

    :param save_freq: calls between two checkpoints (env steps divided by the number of envs)
    :param folder: the checkpoint folder
    :param settings: the run's settings (:func:`save_checkpoint`)
    :param training_s: the wall time of the training before this process's, for a resumed run (its checkpoint's
        ``training_s``); None where unknown (a checkpoint that does not record it): then none is recorded
    """

    def __init__(
        self,
        save_freq: int,
        folder: str | os.PathLike,
        settings: dict[str, Any],
        training_s: float | None = 0.0,
        verbose: int = 0,
    ):
        super().__init__(verbose)
        if save_freq < 1:
            raise ValueError(f"save_freq must be at least 1, got {save_freq}.")
        self.save_freq, self.folder, self.settings = save_freq, Path(folder), settings
        self._before, self._start = training_s, time.perf_counter()

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()

    def training_s(self) -> float | None:
        """The wall time training has taken so far, earlier processes' included; None where unknown."""
        return None if self._before is None else self._before + time.perf_counter() - self._start

    def save(self) -> None:
        """Save a checkpoint now."""
        save_checkpoint(self.model, self.folder, self.settings, self.training_s())  # type: ignore[arg-type]
        if self.verbose:
            print(f"Checkpoint at {self.num_timesteps} env steps in {self.folder}")

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq == 0:
            self.save()
        return True


class RestoreCounters(BaseCallback):
    """
    The counters of a resumed model put back at training start, for a ``learn`` that resets them
    (``reset_num_timesteps=True``, as the RL Zoo calls it): env steps, episodes, the episode statistics, and the call
    counts of ``callbacks`` (so that evaluations and checkpoints keep their env steps). Put it first.

    :param model: the resumed model (:func:`load_checkpoint`), whose counters are read now
    :param callbacks: the other callbacks of the run
    """

    def __init__(self, model: OffPolicyAlgorithm, callbacks: Sequence[BaseCallback] = ()):
        super().__init__()
        self._counters = {
            "num_timesteps": model.num_timesteps,
            "_num_timesteps_at_start": model.num_timesteps,
            "_episode_num": model._episode_num,
            "ep_info_buffer": model.ep_info_buffer,
            "ep_success_buffer": model.ep_success_buffer,
        }
        self._callbacks = list(callbacks)

    def _on_training_start(self) -> None:
        for name, value in self._counters.items():
            if value is not None:
                setattr(self.model, name, value)
        calls = self.model.num_timesteps // self.model.n_envs
        for callback in [self, *self._callbacks]:
            callback.n_calls = calls

    def _on_step(self) -> bool:
        return True
