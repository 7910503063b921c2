"""
A challenge folder's records of its finished stages (``summary.json``'s ``stages``, and the ``stage.json`` markers
where its models are): how a recorded configuration differs from today's, and their migration to today's
configurations where only the way a stage's settings are written has changed (the same hyperparameters reaching the
zoo), so that a committed result still resumes (the command: :mod:`sb3_pilot.experiments.challenges.migrate`).

A folder's challenge, budget and seeds are its ``summary.json``'s; a record is rewritten only when every one of its
stages either has today's configuration already or is a :class:`ZooTrain` whose recorded command line and YAML entry
give the zoo the same hyperparameters and arguments as today's (:func:`same_training`), and when its stored hash is
that of its stored configuration (a hand-edited record is refused, its differences named).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from typing import Any

from sb3_pilot.experiments.challenges.stages import ZooTrain, config_hash, zoo_hyperparams


def _fields(value: Any, path: str) -> Iterator[tuple[str, Any]]:
    """
    A stored configuration as ``(field, value)`` pairs: nested keys joined by dots, and a zoo command line (``zoo``)
    by its options, ``-params`` and ``--env-kwargs`` by their keys (``zoo -params learning_rate``).
    """
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _fields(item, f"{path}.{key}" if path else str(key))
    elif path == "zoo" and isinstance(value, list):
        option, options = "", {}
        for token in value:
            if token.startswith("-") and not token[1:2].isdigit():
                option = token
                options.setdefault(option, [])
            elif option in ("-params", "--env-kwargs", "--eval-env-kwargs"):
                key, _, text = token.partition(":")
                options[f"{option} {key}"] = text
            else:
                options.setdefault(option, []).append(token)
        for key, item in options.items():
            yield f"zoo {key}".rstrip(), " ".join(item) if isinstance(item, list) else item
    else:
        yield path, value


def config_differences(recorded: dict[str, Any], config: dict[str, Any]) -> list[str]:
    """
    :param recorded: a stage's configuration as a record stores it
    :param config: its configuration today
    :return: one ``field: recorded -> today`` line per field that differs (``<none>`` where one has no such field)
    """
    old, new = dict(_fields(recorded, "")), dict(_fields(config, ""))
    missing = "<none>"
    return [
        f"{key}: {old.get(key, missing)!r} -> {new.get(key, missing)!r}"
        for key in [*old, *(key for key in new if key not in old)]
        if old.get(key, missing) != new.get(key, missing)
    ]


def _without_params(args: list[str]) -> list[str]:
    """A zoo command line without its ``-params`` and the name of its ``--conf-file``."""
    start = end = args.index("-params")
    while end + 1 < len(args) and not args[end + 1].startswith("--"):
        end += 1
    rest = args[:start] + args[end + 1 :]
    where = rest.index("--conf-file")
    return rest[:where] + rest[where + 2 :]


#: Where a record from before the YAML entry was stored (no ``preset``) finds the entries its stage may have trained
#: with: ``(key, record) -> entries``, e.g. the YAML as it was when the record was made (:mod:`.migrate`).
PresetLookup = Callable[[str, dict[str, Any]], list[dict[str, Any]]]


class RecordMismatch(ValueError):
    """A record that cannot be migrated: a hand-edited hash, or a stage recorded under other settings."""


def recorded_presets(key: str, entry: dict[str, Any], presets: PresetLookup | None) -> list[dict[str, Any]]:
    """
    The YAML entries a recorded zoo stage may have trained with: its ``preset``, or what ``presets`` finds for a
    record from before the entry was stored.

    :raise RecordMismatch: for a record without ``preset`` and no ``presets`` (today's entry may not be the one it
        trained with)
    """
    if "preset" in entry["config"]:
        return [entry["config"]["preset"]]
    if presets is None:
        raise RecordMismatch(f"{key}: recorded without its YAML entry (preset): name where to find it")
    return presets(key, entry)


def same_training(stage: ZooTrain, recorded: dict[str, Any], preset: dict[str, Any], config: dict[str, Any]) -> bool:
    """
    Whether a recorded zoo stage trained as today's configuration would: the same zoo arguments (but the YAML file's
    name and ``-params``) and the same hyperparameters once the zoo has merged ``-params`` over the YAML entry
    (:func:`~sb3_pilot.experiments.challenges.stages.zoo_hyperparams`).

    :param stage: the stage
    :param recorded: its recorded configuration
    :param preset: the YAML entry it trained with
    :param config: its configuration today
    """
    before = {"zoo": recorded["zoo"], "preset": preset}
    same_args = _without_params(recorded["zoo"]) == _without_params(config["zoo"])
    return same_args and _canonical(zoo_hyperparams(before)) == _canonical(zoo_hyperparams(config))


def training_differences(recorded: dict[str, Any], preset: dict[str, Any], config: dict[str, Any]) -> list[str]:
    """
    What a recorded zoo stage trained with that today's configuration would not: ``name: recorded -> today`` for each
    zoo argument (``zoo --seed``) and hyperparameter (after the zoo's merge) that differs.
    """
    before = {
        "zoo": _without_params(recorded["zoo"]),
        "hyperparams": json.loads(_canonical(zoo_hyperparams({**recorded, "preset": preset}))),
    }
    after = {"zoo": _without_params(config["zoo"]), "hyperparams": json.loads(_canonical(zoo_hyperparams(config)))}
    return config_differences(before, after)


def _canonical(hyperparams: dict[str, Any]) -> str:
    """Hyperparameters as comparable text: keys sorted at every level, classes by their ``repr``."""
    return json.dumps(hyperparams, sort_keys=True, default=repr)


def migrate_stages(
    stages: dict[str, dict[str, Any]],
    tasks: dict[str, Any],
    others: dict[str, dict[str, Any]] | None = None,
    presets: PresetLookup | None = None,
) -> dict[str, str]:
    """
    Today's hash of every recorded stage, checking that each may take it.

    :param stages: the records by ``seed_<k>/<stage>`` (``config_hash``, ``config``), as ``summary.json`` holds them
    :param tasks: today's stages by the same keys (:func:`~sb3_pilot.experiments.challenges.runner.stage_tasks`)
    :param others: records of the stages they read from, where ``stages`` lacks them (the summary's, for markers)
    :param presets: the YAML entries of records without ``preset`` (:func:`recorded_presets`); each must train the same
    :return: the recorded hash -> today's, for every recorded stage
    :raise RecordMismatch: naming the stage and what differs, for a record whose hash is not that of its stored
        configuration and the hashes it read from, or one recorded under other settings than today's
    """
    renamed: dict[str, str] = {}
    known = {**(others or {}), **stages}
    for key, entry in stages.items():
        task = tasks.get(key)
        if task is None:
            raise RecordMismatch(f"{key}: no such stage in the challenge today")
        needs = [known[need]["config_hash"] for need in task.needs if need in known]
        if len(needs) != len(task.needs) or config_hash(entry["config"], needs) != entry["config_hash"]:
            raise RecordMismatch(
                f"{key}: its config_hash {entry['config_hash']} is not the hash of its recorded configuration "
                "and of the stages it reads from (edited by hand?)"
            )
        if entry["config"] != task.config:
            if not isinstance(task.stage, ZooTrain):
                differences = "; ".join(config_differences(entry["config"], task.config))
                raise RecordMismatch(f"{key}: recorded under other settings than today's ({differences})")
            for preset in recorded_presets(key, entry, presets):
                if not same_training(task.stage, entry["config"], preset, task.config):
                    differences = "; ".join(training_differences(entry["config"], preset, task.config))
                    raise RecordMismatch(f"{key}: recorded under other settings than today's ({differences})")
        renamed[entry["config_hash"]] = task.digest
    return renamed


def migrate_summary(summary: dict[str, Any], tasks: dict[str, Any], presets: PresetLookup | None = None) -> dict[str, Any]:
    """
    A ``summary.json`` with every stage's configuration and hash today's (its source's runs' hashes too).

    :param summary: the summary
    :param tasks: today's stages (:func:`migrate_stages`)
    :param presets: as :func:`migrate_stages`
    :raise RecordMismatch: as :func:`migrate_stages`
    """
    renamed = migrate_stages(summary["stages"], tasks, presets=presets)
    stages = {
        key: {**entry, "config_hash": tasks[key].digest, "config": tasks[key].config}
        for key, entry in summary["stages"].items()
    }
    migrated = {**summary, "stages": stages}
    if "source" in summary:
        runs = [
            {**run, "config_hash": renamed.get(run["config_hash"], run["config_hash"])} for run in summary["source"]["runs"]
        ]
        migrated["source"] = {**summary["source"], "runs": runs}
    return migrated
