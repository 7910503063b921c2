"""
A saved model's parts, one rule each: how to load an off-policy model that only acts (without its replay buffer), and
where the RL Zoo keeps the ``VecNormalize`` statistics of a model it saved. The library's readers
(:func:`~sb3_pilot.distill.teacher.load_teacher`, :func:`~sb3_pilot.transfer.load_planner_from`,
:class:`~sb3_pilot.transfer.StatePlannerTransferCallback`) and the experiments' zoo-run reader
(:mod:`sb3_pilot.experiments.zoo_run`) all use them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

#: The file the RL Zoo saves a normalised run's ``VecNormalize`` in, among the model's saved settings.
VECNORMALIZE_FILE = "vecnormalize.pkl"


def without_replay_buffer() -> dict[str, Any]:
    """
    ``custom_objects`` for an off-policy model's ``load`` (``SAC.load(path, custom_objects=...)``) that leaves the
    replay buffer out: no buffer class (a HER buffer could not be built without the env), no room allocated. For a
    model that only acts (rollouts, evaluation, a policy's weights). A new dict each call: the model keeps the objects
    it is loaded with.

    :return: ``{"replay_buffer_class": None, "replay_buffer_kwargs": {}, "buffer_size": 1}``
    """
    return {"replay_buffer_class": None, "replay_buffer_kwargs": {}, "buffer_size": 1}


def zoo_settings_dir(model_path: str | os.PathLike) -> Path:
    """
    :param model_path: a model the RL Zoo saved, ``<run folder>/<env name>.zip``
    :return: the folder of its saved settings, ``<run folder>/<env name>/`` (``args.yml``, ``config.yml`` and, for a
        normalised run, :data:`VECNORMALIZE_FILE`)
    """
    model_path = Path(model_path)
    return model_path.parent / model_path.stem


def vecnormalize_path(model_path: str | os.PathLike) -> Path:
    """
    :param model_path: a model the RL Zoo saved, ``<run folder>/<env name>.zip``
    :return: where the zoo saves its ``VecNormalize`` statistics (if the run normalises):
        ``<run folder>/<env name>/vecnormalize.pkl``
    """
    return zoo_settings_dir(model_path) / VECNORMALIZE_FILE
