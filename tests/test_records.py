"""Committed challenge records: each folder's own command plans no stage; their migration; a hand-edited record."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from typing import Any

import pytest
import yaml

from benchmarks.sources import SOURCE_TASKS, source_challenge
from sb3_pilot.experiments.challenges import CHALLENGES, run_challenge
from sb3_pilot.experiments.challenges.__main__ import main as challenges_main
from sb3_pilot.experiments.challenges.definitions import BUDGETS, REUSE_SHIPPED, VARIANTS, Challenge
from sb3_pilot.experiments.challenges.migrate import main as migrate_main
from sb3_pilot.experiments.challenges.migrate import migrate_folder
from sb3_pilot.experiments.challenges.records import RecordMismatch, config_differences
from sb3_pilot.experiments.challenges.runner import SUMMARY, context_kwargs, stage_tasks
from sb3_pilot.experiments.challenges.stages import REPO_DIR, ZooTrain, config_hash, zoo_hyperparams, zoo_text
from sb3_pilot.experiments.zoo import hyperparams_dir

ZOO_RUNS = REPO_DIR / "zoo_runs"
#: Records under zoo_runs/ that today's command would train again, and why: their UDPO sources trained under an
#: earlier lambda (``planner_coef``) than the YAML entry's today (python -m sb3_pilot.experiments.challenges.migrate
#: FOLDER --presets-from-git names it). The test checks each is still so: re-created, it leaves this list.
NOT_RESUMABLE = {
    "vec-to-image": "source planner_coef 0.01, today 0.001",
    "vec-to-image-reacher": "source planner_coef 0.001, today 0.0001",
    "sources/source-fetchreach": "planner_coef 0.01, today 0.001",
    "sources/source-fetchpush": "an earlier recipe: 100k steps, 8 envs, planner_coef 0.01, ...",
    "sources/source-reacher": "planner_coef 0.01, today 0.0001",
    "sources/source-maze2d": "planner_coef 0.1, today 0.0001",
    "sources/source-pointlocomotion": "planner_coef 0.005, today 0.0001",
    # earlier runs of the sources benchmark kept beside today's (their READMEs tell the story)
    "sources/old-lambda/source-fetchreach": "planner_coef 0.01, today 0.001",
    "sources/old-recipe/source-maze2d": "trained and evaluated on the far goal, today on uniform goals",
    "sources/old-recipe/source-reacher": "4 envs, today 1",
}
SOURCES = {challenge.name: challenge for challenge in map(source_challenge, SOURCE_TASKS)}


def _records() -> list[str]:
    """The committed runner records (``summary.json`` with stages) whose folder is still its challenge's output."""
    found = []
    for path in sorted(ZOO_RUNS.glob("**/summary.json")):
        record = json.loads(path.read_text())
        if "stages" in record and path.parent.name == record.get("challenge"):
            found.append(str(path.parent.relative_to(ZOO_RUNS)))
    return found


def _challenge(record: dict[str, Any]) -> tuple[Challenge, list[str]] | None:
    """A record's challenge today and the command-line words that name it, or None (another era's challenge)."""
    name = record["challenge"]
    if name in CHALLENGES:
        return CHALLENGES[name], [name]
    shipped = {challenge.name: base for base, challenge in REUSE_SHIPPED.items()}
    if name in shipped:
        return REUSE_SHIPPED[shipped[name]], [shipped[name], "--reuse-shipped"]
    variants = {challenge.name: (base, variant) for base, named in VARIANTS.items() for variant, challenge in named.items()}
    if name in variants:
        base, variant = variants[name]
        return VARIANTS[base][variant], [base, "--variant", variant]
    return (SOURCES[name], []) if name in SOURCES else None


def _seeds(record: dict[str, Any]) -> list[int]:
    """The record's finished seeds (a run under way also records the finished stages of the seed it is on)."""
    return sorted(record["seeds"])


def test_the_records_are_found() -> None:
    """The records the next test dry-runs: every challenge folder of the results, the shipped runs, the sources."""
    records = _records()
    assert {"high-dim-action", "vec-to-image", "vec-to-image-reacher", "maze-car-shipped"} <= set(records)
    assert {"high-dim-action-push-shipped", "sources/source-reacher", "maze-car-budget/maze-car"} <= set(records)


@pytest.mark.parametrize("folder", _records())
def test_a_committed_record_plans_no_stage(folder: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Each committed folder's own command (its challenge, budget, seeds and recorded stages) with ``--dry-run``
    finds every stage finished: a fresh clone resumes it instead of training again."""
    record = json.loads((ZOO_RUNS / folder / SUMMARY).read_text())
    found = _challenge(record)
    if found is None or record["budget"] not in BUDGETS:  # a benchmark's own budget or a challenge of another era
        pytest.skip(f"{record['challenge']} at budget {record['budget']}: no command of today")
    challenge, words = found
    seeds, root = _seeds(record), (ZOO_RUNS / folder).parent
    if not words:  # the sources benchmark's challenge: its command calls run_challenge
        plan = run_challenge(challenge, record["budget"], seeds=seeds, root=root, dry_run=True)
    else:
        names = sorted({key.split("/")[1] for key in record["stages"]})
        stages = ["--stages", *names] if set(names) != {stage.name for stage in challenge.stages} else []
        seed_text = ",".join(map(str, seeds)) if len(seeds) > 1 else f"{seeds[0]}-{seeds[0]}"
        command = [*words, "--budget", record["budget"], "--seeds", seed_text, "--root", str(root), *stages]
        challenges_main([*command, "--dry-run"])
        plan = {"to_run": capsys.readouterr().out.splitlines()[0]}
        plan["to_run"] = [] if ": 0 stages to run" in plan["to_run"] else [plan["to_run"]]
    if folder in NOT_RESUMABLE:
        assert plan["to_run"], f"{folder} resumes now: take it off NOT_RESUMABLE"
    else:
        assert plan["to_run"] == []


def _old_layout(config: dict[str, Any], ctx: Any, stage: ZooTrain) -> dict[str, Any]:
    """A zoo stage's configuration as it was written before the recipes moved into YAML: the budget's plain file, and
    the recipe's settings in ``-params``."""
    args = list(config["zoo"])
    conf_file = args[args.index("--conf-file") + 1]
    plain = ctx.budget.conf_dir + stage.conf_file
    base = yaml.safe_load((hyperparams_dir() / plain).read_text())[stage.env_id]
    recipe = yaml.safe_load((hyperparams_dir() / conf_file).read_text())[stage.env_id]
    moved = {key: value for key, value in recipe.items() if base.get(key) != value and key != "n_timesteps"}
    if "policy_kwargs" in moved:
        moved["policy_kwargs"] = eval(moved["policy_kwargs"])
    args[args.index("--conf-file") + 1] = plain
    start = args.index("-params") + 1
    params = dict(item.split(":", 1) for item in args[start:] if ":" in item and not item.startswith("--"))
    written = [f"{key}:{zoo_text(value)}" for key, value in moved.items() if key not in params]
    args[start:start] = written
    return {"zoo": args, "preset": base}


def test_a_record_of_the_old_layout_is_migrated_and_resumes(tmp_path: Path) -> None:
    """High-Dim-Action recorded with its recipe in ``-params`` (as before the recipes moved into YAML): the migration
    checks that each stage trained with the same hyperparameters, rewrites it to today's hashes, and it resumes."""
    challenge, seeds = CHALLENGES["high-dim-action"], [0]
    out_dir = tmp_path / challenge.name
    tasks = stage_tasks(challenge, seeds, out_dir, context_kwargs(challenge, BUDGETS["cpu"]))
    stages, hashes = {}, {}
    for key, task in tasks.items():
        config = _old_layout(task.config, task.ctx, task.stage)
        assert config != task.config and zoo_hyperparams(config) == zoo_hyperparams(task.config)
        hashes[key] = config_hash(config, [hashes[need] for need in task.needs])
        stages[key] = {"config_hash": hashes[key], "wall_time_s": 1.0, "config": config, "progress_csv": None}
    runs = [{"seed": 0, "timesteps": [1], "success_rate": [1.0], "steps_to_50": 1, "steps_to_90": 1}]
    methods = {stage.method: {"stage": stage.name, "runs": runs} for stage in challenge.stages if stage.method}
    source = {"stage": "source", "runs": [{"seed": 0, "final_success": 1.0, "config_hash": hashes["seed_0/source"]}]}
    out_dir.mkdir()
    record = {"challenge": challenge.name, "budget": "cpu", "seeds": seeds, "methods": methods, "stages": stages}
    (out_dir / SUMMARY).write_text(json.dumps({**record, "source": source}))
    assert run_challenge(challenge, "cpu", seeds=seeds, root=tmp_path, dry_run=True)["to_run"] == list(tasks)

    migrate_main([str(out_dir)])
    migrated = json.loads((out_dir / SUMMARY).read_text())
    assert {key: entry["config_hash"] for key, entry in migrated["stages"].items()} == {k: t.digest for k, t in tasks.items()}
    assert migrated["source"]["runs"][0]["config_hash"] == tasks["seed_0/source"].digest
    assert run_challenge(challenge, "cpu", seeds=seeds, root=tmp_path, dry_run=True)["to_run"] == []
    assert migrate_folder(out_dir) == []  # migrated once: nothing left to change


def _copy(folder: str, tmp_path: Path) -> Path:
    out_dir = tmp_path / folder
    out_dir.mkdir()
    shutil.copy(ZOO_RUNS / folder / SUMMARY, out_dir / SUMMARY)
    return out_dir


def test_a_hand_edited_record_names_what_differs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A stage's record edited by hand, so that its hash is no longer today's: the dry-run plans it with the field that
    differs; the migration refuses the folder, naming the stage, whether the hash was edited too or not."""
    out_dir = _copy("high-dim-action", tmp_path)
    record = json.loads((out_dir / SUMMARY).read_text())
    entry = record["stages"]["seed_1/her"]
    entry["config"]["zoo"][entry["config"]["zoo"].index("--eval-episodes") + 1] = "20"
    entry["config_hash"] = config_hash(entry["config"], [])  # the baseline reads from no stage
    (out_dir / SUMMARY).write_text(json.dumps(record))
    challenges_main(["high-dim-action", "--budget", "cpu", "--seeds", "6", "--root", str(tmp_path), "--dry-run"])
    out = capsys.readouterr().out
    assert out.splitlines()[0].startswith("high-dim-action (cpu budget, seeds [0, 1, 2, 3, 4, 5]): 1 stage to run")
    assert "recorded with another configuration: zoo --eval-episodes: '20' -> '10'" in out
    with pytest.raises(RecordMismatch, match=r"seed_1/her: recorded under other settings than today's .*--eval-episodes"):
        migrate_folder(out_dir)
    entry["config_hash"] = "0123456789abcdef"  # a hash edited by hand: the dry-run names it
    (out_dir / SUMMARY).write_text(json.dumps(record))
    challenges_main(["high-dim-action", "--budget", "cpu", "--seeds", "6", "--root", str(tmp_path), "--dry-run"])
    assert "zoo --eval-episodes: '20' -> '10'" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        migrate_main([str(out_dir)])
    assert "seed_1/her: its config_hash 0123456789abcdef is not the hash of its recorded" in capsys.readouterr().err


def test_config_differences_name_the_field() -> None:
    before = {"zoo": ["train", "-n", "8000", "-params", "gamma:0.95"], "preset": {"gamma": 0.99}}
    after = {"zoo": ["train", "-n", "8000", "-params", "gamma:0.98", "tau:0.05"], "preset": {"gamma": 0.99}}
    assert config_differences(before, after) == ["zoo -params gamma: '0.95' -> '0.98'", "zoo -params tau: '<none>' -> '0.05'"]
    assert config_differences(before, before) == []


def test_a_challenge_naming_a_missing_recipe_or_entry_is_refused(tmp_path: Path) -> None:
    """An unknown recipe, or a recipe file without the stage's task, is refused with the names there, before any work."""
    challenge = dataclasses.replace(CHALLENGES["high-dim-action"], recipe="fetch_fast")
    with pytest.raises(ValueError, match=r"no recipe 'fetch_fast' in hyperparams/cpu/ \(its recipes: .*fetch, fetch_push"):
        run_challenge(challenge, "cpu", root=tmp_path, dry_run=True)
    stage = ZooTrain("her", "sac", "Pilot/AntMaze-v0", "sac.yml")
    challenge = dataclasses.replace(CHALLENGES["high-dim-action"], stages=(stage,))
    with pytest.raises(ValueError, match=r"hyperparams/cpu/fetch/sac.yml has no entry 'Pilot/AntMaze-v0' \(its entries: "):
        run_challenge(challenge, "cpu", root=tmp_path, dry_run=True)
    assert not (tmp_path / challenge.name).exists()
    assert run_challenge(challenge, "paper", root=tmp_path, dry_run=True)["to_run"]  # paper reads no recipe


def test_every_recipe_entry_reads_as_the_zoo_reads_it() -> None:
    """Every recipe file under ``hyperparams/cpu/`` holds complete entries of tasks its plain file has, whose strings
    the zoo evaluates (a class in ``policy_kwargs`` written as the expression that imports it)."""
    recipes = [path for path in (hyperparams_dir() / "cpu").iterdir() if path.is_dir()]
    assert {challenge.recipe for challenge in CHALLENGES.values()} - {None} <= {path.name for path in recipes}
    for recipe in recipes:
        for path in recipe.glob("*.yml"):
            plain = yaml.safe_load((path.parent.parent / path.name).read_text())
            for env_id, entry in yaml.safe_load(path.read_text()).items():
                assert set(plain[env_id]) <= set(entry), (path, env_id)
                values = zoo_hyperparams({"zoo": ["train", "-params"], "preset": entry})
                assert isinstance(values.get("policy_kwargs", {}), dict), (path, env_id)
