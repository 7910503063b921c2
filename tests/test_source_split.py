"""The rows over the seeds whose trained source learned: recorded in summary.json, split in both tables, a hint at most."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from sb3_pilot.experiments.challenges import BUDGETS, CHALLENGES, format_table
from sb3_pilot.experiments.challenges.definitions import HER, PLANNER_TRANSFER
from sb3_pilot.experiments.challenges.runner import SOURCE_LEARNED, SUMMARY, plan, summarize
from sb3_pilot.experiments.challenges.stages import REPO_DIR, zoo_run_dir
from sb3_pilot.experiments.pairs import add_statistics, table
from sb3_pilot.experiments.statistics import SOURCE_LEARNED_SUBSET, compare, summary_statistics, verdict

CHALLENGE = CHALLENGES["high-dim-action-push"]  # source -> pilot (its frozen state planner); her from scratch
STEPS = [25_000, 50_000, 75_000, 100_000]
#: Each seed's source: its success at each evaluation (seeds 0 and 2 end at 0.5 or above: they learned).
SOURCE_CURVES = {0: [0.0, 0.1, 0.6, 0.9], 1: [0.0, 0.1, 0.2, 0.3], 2: [0.0, 0.5, 0.4, 0.5]}
REPS = 200


def curve(start: float) -> list[float]:
    """A success curve rising from 0 at ``start`` to 1 over 50k steps."""
    return np.clip((np.array(STEPS) - start) / 50_000, 0, 1).tolist()


def make_run(out_dir: Path, curves: dict[str, dict[int, list[float]]]) -> dict[str, dict]:
    """
    A finished run of the challenge without training: every stage's ``evaluations.npz`` where the zoo writes it.

    :param out_dir: ``<root>/<challenge>``
    :param curves: success per evaluation, by stage and seed
    :return: the stage markers by ``seed_<k>/<stage>``
    """
    markers = {}
    stages = {stage.name: stage for stage in CHALLENGE.stages}
    for name, by_seed in curves.items():
        for seed, success in by_seed.items():
            folder = zoo_run_dir(out_dir / "models" / f"seed_{seed}" / name, stages[name].algo, stages[name].env_id)
            folder.mkdir(parents=True)
            # 10 episodes an evaluation, as many successes as the rate says
            successes = (np.arange(10)[None, :] < np.round(np.array(success) * 10)[:, None]).astype(np.float64)
            np.savez(folder / "evaluations.npz", timesteps=np.array(STEPS), successes=successes)
            markers[f"seed_{seed}/{name}"] = {"config_hash": f"{name}{seed}", "wall_time_s": 1.0, "config": {}}
    return markers


def target_curves(seeds: list[int]) -> dict[str, dict[int, list[float]]]:
    """The sources above; the transfer learns early on the seeds whose source learned, scratch late on every seed."""
    learned = [seed for seed in seeds if SOURCE_CURVES[seed][-1] >= SOURCE_LEARNED]
    return {
        "source": {seed: SOURCE_CURVES[seed] for seed in seeds},
        "pilot": {seed: curve(0 if seed in learned else 60_000) for seed in seeds},
        "her": {seed: curve(50_000) for seed in seeds},
    }


def test_the_subset_verdict_is_at_most_a_hint() -> None:
    """Seeds chosen after the fact: an interval above 0 on enough seeds is a hint, below 0 no gain shown; said so."""
    above, below, around = ({"value": v, "ci": ci} for v, ci in ((0.3, [0.2, 0.4]), (-0.3, [-0.4, -0.2]), (0.1, [-0.1, 0.3])))
    chosen = f", a subset chosen after the fact ({SOURCE_LEARNED_SUBSET})"
    assert verdict(above, 6) == "confirmed: area gain +0.30 [+0.20, +0.40]"
    assert (
        verdict(above, 6, SOURCE_LEARNED_SUBSET)
        == f"a hint: area gain +0.30 [+0.20, +0.40] above 0 on 6 seeds per method{chosen}"
    )
    assert verdict(above, 3, SOURCE_LEARNED_SUBSET).endswith(f"on 3 seeds per method (5 needed){chosen}")
    assert verdict(below, 6, SOURCE_LEARNED_SUBSET).startswith("no gain shown") and verdict(below, 6).startswith("worse")
    assert verdict(around, 6, SOURCE_LEARNED_SUBSET) == f"a hint: area gain +0.10 [-0.10, +0.30] includes 0{chosen}"
    assert verdict(above, 2, SOURCE_LEARNED_SUBSET).startswith("too few seeds (2)")


def test_subset_statistics_seeds_counts_and_verdict() -> None:
    """Six of ten sources learned: PILoT over those six against SAC+HER's ten; a clear gain there is a hint only."""
    rng = np.random.default_rng(0)
    seeds, learned = list(range(10)), [0, 2, 3, 5, 7, 8]
    pilot = [
        {"seed": s, "timesteps": STEPS, "success_rate": curve(rng.uniform(-40_000, 0) if s in learned else 90_000)}
        for s in seeds
    ]
    her = [{"seed": s, "timesteps": STEPS, "success_rate": curve(rng.uniform(40_000, 60_000))} for s in seeds]
    source = {
        "stage": "source",
        "env_id": "Pilot/FetchPush-v0",
        "learned_at": SOURCE_LEARNED,
        "methods": ["PILoT"],
        "runs": [
            {"seed": s, "final_success": 0.9 * (s in learned), "learned": s in learned, "config_hash": f"h{s}"} for s in seeds
        ],
    }
    summary = {"seeds": [*seeds, 10], "methods": {"PILoT": {"runs": pilot, "sources": 10}, HER: {"runs": her, "sources": 0}}}
    summary["source"] = source
    statistics = summary_statistics(summary, HER, reps=REPS)
    split = statistics["source_learned"]
    assert (split["seeds"], split["of"], split["not_recorded"], split["learned_at"]) == (learned, seeds, [10], SOURCE_LEARNED)
    assert set(split["methods"]) == set(split["comparisons"]) == {"PILoT"}  # SAC+HER reads no source: no subset row
    stats, comparison = split["methods"]["PILoT"], split["comparisons"]["PILoT"]
    assert (stats["seeds"], stats["sources"], stats["aggregate"]) == (6, 6, "IQM")
    assert comparison["seeds"] == {"method": 6, "baseline": 10}
    assert comparison["area_gain"]["ci"][0] > 0  # the interval excludes 0 on 6 seeds, which would confirm it ...
    subset = [run for run in pilot if run["seed"] in learned]
    assert compare(subset, her, reps=REPS)["verdict"].startswith("confirmed")
    assert comparison["verdict"].startswith("a hint") and SOURCE_LEARNED_SUBSET in comparison["verdict"]  # ... not here
    assert not statistics["comparisons"]["PILoT"]["verdict"].startswith("confirmed")  # the headline, over all seeds
    for flags in ([True] * 10, [False] * 10):  # every source learned, or none: no subset rows
        summary["source"] = {
            **source,
            "runs": [{**run, "learned": flag} for run, flag in zip(source["runs"], flags, strict=True)],
        }
        split = summary_statistics(summary, HER, reps=REPS)["source_learned"]
        assert split["methods"] == split["comparisons"] == {} and len(split["seeds"]) in (0, 10)


def test_summary_records_the_source_and_the_tables_split(tmp_path: Path) -> None:
    """summarize reads each seed's source evaluations; format_table and the pairs table add the subset rows."""
    out_dir, seeds = tmp_path / CHALLENGE.name, [0, 1, 2]
    markers = make_run(out_dir, target_curves(seeds))
    summary = summarize(CHALLENGE, BUDGETS["cpu"], seeds, out_dir, markers)
    source = summary["source"]
    assert (source["stage"], source["env_id"], source["learned_at"]) == ("source", "Pilot/FetchPush-v0", SOURCE_LEARNED)
    assert source["methods"] == [PLANNER_TRANSFER]  # SAC+HER reads no source
    assert source["runs"] == [
        {
            "seed": 0,
            "final_success": 0.9,
            "steps_to_50": 75_000,
            "steps_to_90": 100_000,
            "learned": True,
            "config_hash": "source0",
        },
        {
            "seed": 1,
            "final_success": 0.3,
            "steps_to_50": None,
            "steps_to_90": None,
            "learned": False,
            "config_hash": "source1",
        },
        {
            "seed": 2,
            "final_success": 0.5,
            "steps_to_50": 50_000,
            "steps_to_90": None,
            "learned": True,
            "config_hash": "source2",
        },
    ]
    rows = format_table(summary).splitlines()  # 3 seeds without statistics: the subset's finals and steps
    label = "only the seeds whose source learned (a subset chosen after the fact: at most a hint)"
    subset = f"| {PLANNER_TRANSFER}, {label} | 2 (2 sources) |"
    assert len(rows) == 3 + 2 + 1 + 1 and rows[5].startswith(subset) and "1.00 [1.00, 1.00]" in rows[5]
    assert rows[-1].startswith(
        "Sources: 2 of 3 seeds' sources learned (the source stage's final success >= 0.5 on Pilot/FetchPush-v0: seeds [0, 2])"
    )
    summary["statistics"] = summary_statistics(summary, HER, reps=REPS)
    rows = format_table(summary).splitlines()
    assert rows[5].startswith(subset) and rows[5].endswith(f"a subset chosen after the fact ({SOURCE_LEARNED_SUBSET}) |")
    assert "a hint" in rows[5] and rows[3].startswith(f"| {PLANNER_TRANSFER} | 3 (3 sources) |")

    # an older summary.json, written before the runner recorded the source: pairs reads it from the models
    del summary["source"], summary["statistics"]
    (out_dir / SUMMARY).write_text(json.dumps({**summary, "stages": markers}))
    lines = table([out_dir], reps=REPS).splitlines()
    assert json.loads((out_dir / SUMMARY).read_text())["source"] == source
    assert len(lines) == 2 + 2 + 1 and all(line.count("|") == 13 for line in lines)
    assert "(cpu, 3 seeds; 2 of 3 seeds' sources learned" in lines[2]
    assert lines[4].startswith(f"| {CHALLENGE.name}, only the 2 seeds whose source learned (a subset chosen after the fact")
    assert f"| {PLANNER_TRANSFER} | 2 (2 sources) | 100000 | mean " in lines[4] and "a hint" in lines[4]


def test_a_recorded_source_outlives_its_models(tmp_path: Path) -> None:
    """On a fresh clone (models gone) the source's record in summary.json is kept, as the methods' runs are."""
    out_dir, seeds = tmp_path / CHALLENGE.name, [0, 1]
    budget = BUDGETS["cpu"]
    ctx = {"budget": budget, "steps": CHALLENGE.steps["cpu"], "recipe": CHALLENGE.recipe}
    tasks, _ = plan(CHALLENGE, seeds, out_dir, ctx)
    markers = make_run(out_dir, target_curves(seeds))
    for task in tasks:  # the hashes plan computes, as a finished run's markers hold them
        markers[task.key]["config_hash"] = task.digest
    summary = summarize(CHALLENGE, budget, seeds, out_dir, markers)
    shutil.rmtree(out_dir / "models")
    (out_dir / SUMMARY).write_text(json.dumps(summary))
    tasks, finished = plan(CHALLENGE, seeds, out_dir, ctx)
    assert tasks == [] and finished["seed_1/source"]["from_summary"]
    again = summarize(CHALLENGE, budget, seeds, out_dir, finished)
    assert again["source"] == summary["source"] and again["methods"] == summary["methods"]


@pytest.mark.parametrize("folder", ["complex-morph-earlier-presets", "high-dim-action-push-shipped"])
def test_older_summaries_load_without_a_split(tmp_path: Path, folder: str) -> None:
    """Committed summaries from before the source was recorded (models gone), or with a shipped source: no subset."""
    run_dir = tmp_path / folder
    run_dir.mkdir()
    for name in ("summary.json", "final_eval.json"):
        shutil.copy(REPO_DIR / "zoo_runs" / folder / name, run_dir / name)
    summary = add_statistics(run_dir, reps=20)
    assert "source" not in summary and "source_learned" not in summary["statistics"]
    lines = table([run_dir], reps=20).splitlines()
    assert len(lines) == 2 + len(summary["methods"]) and "sources learned" not in lines[2]
    assert "only the seeds" not in format_table(summary)


def test_a_finished_method_of_an_unfinished_seed_outlives_its_models(tmp_path: Path) -> None:
    """SAC + HER finished on seed 1 while its source did not: summary.json keeps that run apart from the statistics, and
    a fresh clone trains seed 1's source and transfer only."""
    out_dir, seeds = tmp_path / CHALLENGE.name, [0, 1]
    budget = BUDGETS["cpu"]
    ctx = {"budget": budget, "steps": CHALLENGE.steps["cpu"], "recipe": CHALLENGE.recipe}
    tasks, _ = plan(CHALLENGE, seeds, out_dir, ctx)
    markers = make_run(out_dir, target_curves(seeds))
    for task in tasks:
        markers[task.key]["config_hash"] = task.digest
    del markers["seed_1/source"], markers["seed_1/pilot"]  # stopped (or never started) before they finished
    summary = summarize(CHALLENGE, budget, [0], out_dir, markers)
    assert [run["seed"] for run in summary["methods"][HER]["runs"]] == [0]
    assert summary["partial_runs"]["seed_1/her"]["success_rate"] == curve(50_000)
    assert list(summary["partial_runs"]) == ["seed_1/her"]
    shutil.rmtree(out_dir / "models")
    (out_dir / SUMMARY).write_text(json.dumps(summary))
    tasks, finished = plan(CHALLENGE, seeds, out_dir, ctx)
    assert [task.key for task in tasks] == ["seed_1/source", "seed_1/pilot"]
    her = finished["seed_1/her"]
    assert her["from_summary"] and her["recorded"] == summary["partial_runs"]["seed_1/her"]
    # written again before seed 1 finishes (its models gone), the run is still kept
    assert summarize(CHALLENGE, budget, [0], out_dir, finished)["partial_runs"] == summary["partial_runs"]
