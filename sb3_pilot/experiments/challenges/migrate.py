"""
``python -m sb3_pilot.experiments.challenges.migrate FOLDER [FOLDER ...] [--presets-from-git]``: rewrite challenge
folders' records (``summary.json``, stage markers) to today's stage configurations where they train the same
(:func:`migrate_folder`), each folder whole or not at all; e.g. after the
challenges' settings moved from Python into their YAML recipes::

    python -m sb3_pilot.experiments.challenges.migrate zoo_runs/high-dim-action zoo_runs/maze-car-shipped \
        --presets-from-git

A record from before the stages' YAML entries were stored (no ``preset``) is checked against the entry as the
repository held it when the record was committed (``--presets-from-git``: the YAML files of the commit that first
wrote the stage's hash and of its parent, both of which must train the same as today's).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import yaml

from sb3_pilot.experiments.challenges.definitions import BUDGETS, CHALLENGES, REUSE_SHIPPED, at_budget
from sb3_pilot.experiments.challenges.records import PresetLookup, RecordMismatch, migrate_stages, migrate_summary
from sb3_pilot.experiments.challenges.runner import SUMMARY, context_kwargs, stage_tasks, write_record
from sb3_pilot.experiments.challenges.stages import REPO_DIR, STAGE_MARKER


def migrate_folder(out_dir: Path, challenge: Any = None, presets: PresetLookup | None = None) -> list[str]:
    """
    Migrate a challenge folder's ``summary.json`` (and its stage markers, where its models are) to today's
    configurations, each stage checked by :func:`~sb3_pilot.experiments.challenges.records.migrate_stages`; nothing
    is written where one fails.

    :param out_dir: ``<root>/<challenge>``
    :param challenge: its :class:`~sb3_pilot.experiments.challenges.definitions.Challenge` (None: the one its summary
        names, in ``CHALLENGES`` or ``REUSE_SHIPPED``)
    :param presets: the YAML entries of records without ``preset``
        (:func:`~sb3_pilot.experiments.challenges.records.recorded_presets`)
    :return: the keys of the stages whose record changed
    :raise RecordMismatch: as :func:`~sb3_pilot.experiments.challenges.records.migrate_stages`
    :raise ValueError: for a challenge or budget unknown today
    """
    summary = json.loads((out_dir / SUMMARY).read_text())
    known = {**CHALLENGES, **{shipped.name: shipped for shipped in REUSE_SHIPPED.values()}}
    challenge = challenge or known.get(summary["challenge"])
    if challenge is None or summary["budget"] not in BUDGETS:
        raise ValueError(
            f"{out_dir}: its challenge {summary['challenge']!r} at budget {summary['budget']!r} is not one of today's "
            f"(challenges: {', '.join(known)}; budgets: {', '.join(BUDGETS)})"
        )
    challenge = at_budget(challenge, summary["budget"])  # its own stages at that budget, if it has any
    seeds = sorted({int(key.split("/")[0].removeprefix("seed_")) for key in summary["stages"]})
    tasks = stage_tasks(challenge, seeds, out_dir.resolve(), context_kwargs(challenge, BUDGETS[summary["budget"]]))
    migrated = migrate_summary(summary, tasks, presets)
    markers = {key: tasks[key].stage_dir / STAGE_MARKER for key in tasks if (tasks[key].stage_dir / STAGE_MARKER).exists()}
    marker_records = {key: json.loads(path.read_text()) for key, path in markers.items()}
    migrate_stages(marker_records, tasks, summary["stages"], presets)
    changed = [key for key, entry in summary["stages"].items() if entry != migrated["stages"][key]]
    if changed:
        write_record(out_dir, migrated)
    for key, path in markers.items():
        marker = {**marker_records[key], "config_hash": tasks[key].digest, "config": tasks[key].config}
        path.write_text(json.dumps(marker, indent=2, default=str))  # as the runner writes it
    return changed


def _git(*args: str) -> str:
    """The output of ``git ARGS`` in the repository ("" where it fails: a file not in that commit)."""
    return subprocess.run(["git", "-C", str(REPO_DIR), *args], capture_output=True, text=True).stdout


def git_presets(out_dir: Path) -> PresetLookup:
    """
    The YAML entries a committed record without ``preset`` trained with, from the repository's history: those of the
    first commit that wrote the stage's hash under ``zoo_runs/`` (wherever the folder was then) and of its parent (the
    run came between them).

    :param out_dir: the challenge folder (unused: the hash finds the commit), for the signature of a lookup
    """

    def lookup(key: str, entry: dict[str, Any]) -> list[dict[str, Any]]:
        first = _git("log", "-S", entry["config_hash"], "--format=%H", "--reverse", "--", "zoo_runs").split()
        if not first:
            raise RecordMismatch(f"{key}: its hash {entry['config_hash']} is in no commit of this repository")
        args = entry["config"]["zoo"]
        conf_file, env_id = args[args.index("--conf-file") + 1], args[args.index("--env") + 1]
        presets = []
        for commit in (f"{first[0]}^", first[0]):
            entries = yaml.safe_load(_git("show", f"{commit}:hyperparams/{conf_file}") or "{}") or {}
            if env_id not in entries:
                raise RecordMismatch(f"{key}: hyperparams/{conf_file} has no entry {env_id!r} at commit {commit}")
            presets.append(entries[env_id])
        return presets

    return lookup


def main(argv: list[str] | None = None) -> None:
    """Migrate the folders named on the command line (each whole or not at all)."""
    parser = argparse.ArgumentParser(
        prog="python -m sb3_pilot.experiments.challenges.migrate",
        description="Rewrite challenge folders' records to today's stage configurations where they train the same.",
    )
    parser.add_argument("folders", nargs="+", type=Path, help="challenge folders (ROOT/CHALLENGE) with a summary.json")
    parser.add_argument(
        "--presets-from-git",
        action="store_true",
        help="records without their YAML entry: check them against the entry the repository held when they were committed",
    )
    args = parser.parse_args(argv)
    failed = False
    for folder in args.folders:
        try:
            changed = migrate_folder(folder, presets=git_presets(folder) if args.presets_from_git else None)
        except ValueError as error:  # RecordMismatch included
            print(f"{folder}: not migrated: {error}", file=sys.stderr)
            failed = True
            continue
        print(f"{folder}: {len(changed)} stage records migrated")
    if failed:
        sys.exit(1)


if __name__ == "__main__":
    main()
