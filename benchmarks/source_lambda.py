"""
UDPO's lambda (``planner_coef``) on the sources: the table of every measured curve, and the High-Dim-Action transfer
from sources trained at each lambda.

``table`` renders ``curves.json`` (per task and method, each seed's evaluation curve and last ``rollout/plan_error``)
as a markdown table with ``sb3_pilot.experiments.statistics`` (IQM over seeds of the steps to 90%, the final success
and the area under the success curve, stratified-bootstrap 95% intervals); ``--add-high-dim ROOT COEF`` first adds the
runs of ``high-dim --root ROOT --coefs COEF`` to ``curves.json``.

``high-dim`` runs the ``high-dim-action`` challenge (UDPO on ``Pilot/FetchReach-v0`` -> its state planner, frozen, in a
UDPO on ``Pilot/FetchReachHighDim-v0``, against SAC + HER) with the *source* UDPO's ``planner_coef`` set to each
lambda (the target's planner is frozen, so its own lambda does not act). It writes ``ROOT/lambda_<LAMBDA>/high-dim-
action/``; SAC + HER does not depend on lambda: its stage folders are copied from the first lambda's run (the same
configuration hash, so the runner reuses them), or it is left out (``--no-her``). From the repository root::

    OMP_NUM_THREADS=1 MUJOCO_GL=osmesa python -m benchmarks.source_lambda high-dim --seeds 3 --coefs 0.0001 --no-her \\
        --root runs/lambda_high_dim
    python -m benchmarks.source_lambda table --add-high-dim runs/lambda_high_dim 0.0001 > zoo_runs/sources/lambda/table.md
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from sb3_pilot.experiments.challenges import CHALLENGES, run_challenge
from sb3_pilot.experiments.statistics import method_statistics

CURVES = Path("zoo_runs/sources/lambda/curves.json")
#: The High-Dim-Action rows: the source (FetchReach, 8k steps) and the transfer (FetchReachHighDim, 8k), by stage.
HIGH_DIM_TASKS = {"high-dim-action: source Pilot/FetchReach-v0": "source", "high-dim-action: transfer": "pilot"}


@dataclasses.dataclass(frozen=True)
class PlannerCoef:
    """The source stage's ``-params``: its lambda."""

    value: float

    def __call__(self, outputs: dict[str, Path]) -> dict[str, Any]:
        return {"planner_coef": self.value}


def npz_curve(path: Path) -> dict[str, list]:
    """The zoo's ``evaluations.npz`` as a curve: steps and mean success per evaluation."""
    data = np.load(path)
    return {"timesteps": data["timesteps"].tolist(), "success_rate": data["successes"].mean(axis=1).round(3).tolist()}


def last_plan_error(path: Path) -> float | None:
    """The last ``rollout/plan_error`` (the planner's mean against the real next state, MSE per dimension) of a
    challenge stage's ``progress.csv`` (None if it has none)."""
    if not path.exists():
        return None
    values = [row["rollout/plan_error"] for row in csv.DictReader(path.open()) if row.get("rollout/plan_error")]
    return round(float(values[-1]), 3) if values else None


def add_high_dim(tasks: dict[str, Any], root: Path, coef: str) -> None:
    """The runs of ``high-dim --coefs COEF --root ROOT`` (seeds 0-2), as rows "UDPO lambda COEF (source's)"."""
    challenge = root / f"lambda_{float(coef):g}/high-dim-action"
    for task, stage in HIGH_DIM_TASKS.items():
        runs = []
        for seed in range(3):
            found = sorted((challenge / f"models/seed_{seed}/{stage}").glob("**/evaluations.npz"))
            if found:
                plan_error = last_plan_error(challenge / f"models/seed_{seed}/{stage}/progress.csv")
                runs.append({"seed": seed, **npz_curve(found[0]), "final_plan_error": plan_error})
        if not runs:
            raise FileNotFoundError(f"no {stage} evaluations under {challenge}/models/seed_*")
        tasks.setdefault(task, {})[f"UDPO lambda {float(coef):g} (source's)"] = runs


def _estimate(entry: dict[str, Any], scale: float = 1.0, unit: str = "") -> str:
    value, (low, high) = entry["value"], entry["ci"]
    if scale != 1.0:
        return f"{value / scale:.3g}{unit} [{low / scale:.3g}, {high / scale:.3g}]"
    return f"{value:.2f} [{low:.2f}, {high:.2f}]"


def table(tasks: dict[str, Any]) -> str:
    """
    :param tasks: ``curves.json``: per task, per method, the runs (``seed``, ``timesteps``, ``success_rate``, and
        optionally ``final_plan_error``)
    :return: the markdown table
    """
    lines = [
        "| task | method | seeds | steps to 90% IQM [95% CI] (reached) | final success IQM [CI] | area IQM [CI] "
        "| per seed: steps to 90% | final plan error per seed |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for task, methods in tasks.items():
        for i, (method, runs) in enumerate(methods.items()):
            if not runs:
                continue
            stats = method_statistics(runs)
            steps = stats["steps_to_90"]
            per_seed = []
            for run in runs:
                hit = [t for t, s in zip(run["timesteps"], run["success_rate"], strict=True) if s >= 0.9]
                per_seed.append(f"{hit[0] / 1000:g}k" if hit else "-")
            errors = [run.get("final_plan_error") for run in runs]
            plan_errors = " / ".join(f"{e:.3g}" for e in errors) if all(e is not None for e in errors) else ""
            lines.append(
                f"| {task if i == 0 else ''} | {method} | {stats['seeds']} | {_estimate(steps, 1000, 'k')} "
                f"({steps['reached']}/{stats['seeds']}, censored at {steps['censored_at'] / 1000:g}k) | "
                f"{_estimate(stats['final_success'])} | {_estimate(stats['area'])} | {' / '.join(per_seed)} | {plan_errors} |"
            )
    return "\n".join(lines)


def high_dim(budget: str, seeds: int, coefs: list[float], root: Path, no_her: bool) -> None:
    """Run the ``high-dim-action`` challenge once per source lambda, into ``root/lambda_<coef>/``."""
    base = CHALLENGES["high-dim-action"]
    first = None
    for coef in coefs:
        stages = tuple(
            dataclasses.replace(stage, params=PlannerCoef(coef)) if stage.name == "source" else stage
            for stage in base.stages
            if not (no_her and stage.name == "her")
        )
        coef_root = root / f"lambda_{coef:g}"
        if first is not None and not no_her:
            for seed in range(seeds):
                her = Path(f"models/seed_{seed}/her")
                if not (coef_root / base.name / her).exists():
                    shutil.copytree(first / base.name / her, coef_root / base.name / her)
        run_challenge(dataclasses.replace(base, stages=stages), budget, seeds=range(seeds), root=coef_root)
        first = first or coef_root


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True)
    render = commands.add_parser("table", help="print the table of curves.json")
    render.add_argument("--curves", type=Path, default=CURVES)
    render.add_argument("--add-high-dim", nargs=2, metavar=("ROOT", "COEF"), help="high-dim's --root and one of its --coefs")
    run = commands.add_parser("high-dim", help="High-Dim-Action with the source's lambda set")
    run.add_argument("--budget", default="cpu")
    run.add_argument("--seeds", type=int, default=3)
    run.add_argument("--coefs", type=float, nargs="+", default=[1e-2, 0.0, 1e-3])
    run.add_argument("--root", type=Path, default=Path("runs/lambda_high_dim"))
    run.add_argument("--no-her", action="store_true", help="leave out SAC + HER (it does not depend on lambda)")
    args = parser.parse_args()
    if args.command == "high-dim":
        high_dim(args.budget, args.seeds, args.coefs, args.root, args.no_her)
        return
    if not args.curves.is_file():
        parser.error(f"{args.curves} not found (run from the repository root, or pass --curves)")
    tasks = json.loads(args.curves.read_text())
    if args.add_high_dim:
        add_high_dim(tasks, Path(args.add_high_dim[0]), args.add_high_dim[1])
        args.curves.write_text(json.dumps(tasks, indent=1))
    print(table(tasks))


if __name__ == "__main__":
    main()
