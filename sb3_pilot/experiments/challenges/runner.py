"""Run a challenge for several seeds and write its ``summary.json``."""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch as th

from sb3_pilot.experiments.challenges.definitions import BUDGETS, CHALLENGES, Challenge
from sb3_pilot.experiments.challenges.stages import Budget, StageContext, run_stage

#: Success rates whose first crossing the summary reports (``steps_to_50``, ``steps_to_90``).
THRESHOLDS = (0.5, 0.9)
SUMMARY = "summary.json"


def steps_to(timesteps: Sequence[int], success_rate: Sequence[float]) -> dict[str, int | None]:
    """
    :return: for each of :data:`THRESHOLDS`, the first evaluated env step whose success rate reaches it (None: never)
    """
    return {
        f"steps_to_{round(100 * threshold)}": next(
            (int(step) for step, rate in zip(timesteps, success_rate, strict=True) if rate >= threshold), None
        )
        for threshold in THRESHOLDS
    }


def summarize(
    challenge: Challenge, budget: Budget, seeds: Sequence[int], out_dir: Path, markers: dict[str, dict[str, Any]]
) -> dict[str, Any]:
    """
    The challenge's results: success rate vs env steps on the target task, per compared method and seed, their
    mean over seeds, and the steps to 50% / 90% success.

    :param challenge: the challenge
    :param budget: the budget it ran at
    :param seeds: seeds whose stages all finished
    :param out_dir: ``<root>/<challenge>``
    :param markers: stage markers by ``seed_<k>/<stage>``
    :return: the summary (what ``summary.json`` holds)
    """
    methods: dict[str, Any] = {}
    for stage in challenge.stages:
        if stage.method is None:
            continue
        runs = []
        for seed in seeds:
            timesteps, success_rate = stage.curve(out_dir / "models" / f"seed_{seed}" / stage.name)
            runs.append(
                {"seed": seed, "timesteps": timesteps, "success_rate": success_rate, **steps_to(timesteps, success_rate)}
            )
        n_points = min(len(run["timesteps"]) for run in runs)
        timesteps = runs[0]["timesteps"][:n_points]
        mean = np.mean([run["success_rate"][:n_points] for run in runs], axis=0).tolist()
        methods[stage.method] = {
            "stage": stage.name,
            "env_id": stage.env_id,
            "runs": runs,
            "mean": {"timesteps": timesteps, "success_rate": mean, **steps_to(timesteps, mean)},
        }
    stages: dict[str, Any] = {}
    for key, marker in markers.items():
        stage_dir = out_dir / "models" / key
        csv = stage_dir / "progress.csv"
        stages[key] = {
            "config_hash": marker["config_hash"],
            "wall_time_s": round(marker["wall_time_s"], 1),
            "config": marker["config"],
            "progress_csv": str(csv.relative_to(out_dir)) if csv.exists() else None,
        }
    return {
        "challenge": challenge.name,
        "description": challenge.description,
        "target_env": challenge.target_env,
        "budget": budget.name,
        "seeds": list(seeds),
        "thresholds": list(THRESHOLDS),
        "methods": methods,
        "stages": stages,
        "wall_time_s": round(sum(marker["wall_time_s"] for marker in markers.values()), 1),
    }


def run_challenge(
    name: str,
    budget: str | Budget = "smoke",
    seeds: Sequence[int] = (0,),
    root: str | Path = "zoo_runs",
    steps: dict[str, int] | None = None,
    progress: bool = False,
    verbose: int = 0,
) -> dict[str, Any]:
    """
    Run (or resume) a challenge: every stage for every seed, seed after seed, then write ``summary.json`` (also
    after each seed, so a long run shows its results as they come).

    :param name: a key of :data:`~sb3_pilot.challenges.CHALLENGES`
    :param budget: a key of :data:`~sb3_pilot.challenges.BUDGETS` or a custom :class:`Budget`
    :param seeds: the seeds
    :param root: output root; the challenge writes into ``<root>/<name>/``
    :param steps: env steps per stage, overriding the budget's (e.g. the demo's)
    :param progress: show progress bars (the zoo's, the distillation's)
    :param verbose: 1 lets the zoo and SB3 print their logs
    :return: the summary
    """
    if name not in CHALLENGES:
        raise ValueError(f"Unknown challenge {name!r}, choose one of {sorted(CHALLENGES)}.")
    challenge = CHALLENGES[name]
    budget = BUDGETS[budget] if isinstance(budget, str) else budget
    out_dir = Path(root).resolve() / name
    stage_steps = {**challenge.steps.get(budget.name, {}), **(steps or {})}
    fast = challenge.fast_hyperparams if budget.fast else {}
    th.set_num_threads(1)  # 2 busy cores: one torch thread is the fastest (the zoo stages also pass --num-threads 1)
    markers: dict[str, dict[str, Any]] = {}
    summary: dict[str, Any] = {}
    n_jobs, job, start = len(seeds) * len(challenge.stages), 0, time.perf_counter()
    for done, seed in enumerate(seeds):
        ctx = StageContext(
            out_dir / "models" / f"seed_{seed}", seed, budget, stage_steps, fast, progress=progress, verbose=verbose
        )
        hashes: dict[str, str] = {}
        for stage in challenge.stages:
            job += 1
            label = f"[{name} {budget.name} {job}/{n_jobs} {time.perf_counter() - start:.0f}s] seed {seed}"
            markers[f"seed_{seed}/{stage.name}"] = run_stage(stage, ctx, hashes, label)
        summary = summarize(challenge, budget, seeds[: done + 1], out_dir, markers)
        (out_dir / SUMMARY).write_text(json.dumps(summary, indent=1))
    print(format_table(summary))
    return summary


def format_table(summary: dict[str, Any]) -> str:
    """A markdown table of a summary: final success (mean [min, max] over seeds) and steps to 50% / 90%."""
    lines = [
        f"{summary['challenge']} ({summary['budget']} budget, seeds {summary['seeds']}) on {summary['target_env']}",
        "| method | env steps | final success, mean [min, max] | steps to 50% | steps to 90% |",
        "|---|---|---|---|---|",
    ]
    for method, result in summary["methods"].items():
        finals = [run["success_rate"][-1] for run in result["runs"]]
        mean = result["mean"]
        lines.append(
            f"| {method} | {mean['timesteps'][-1]} | {np.mean(finals):.2f} [{min(finals):.2f}, {max(finals):.2f}] | "
            f"{mean['steps_to_50'] or '-'} | {mean['steps_to_90'] or '-'} |"
        )
    return "\n".join(lines)
