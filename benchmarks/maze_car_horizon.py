"""
Maze-Car past its budget: SAC+HER and HER+PILoT (displacement cosine) for 40k steps instead of the ``cpu`` budget's
20k, so that every seed's steps to 90% are measured rather than censored.

``run``: the ``maze-car --reuse-shipped`` challenge unchanged (the shipped Maze2D planner, the ``cpu`` budget's 64x64
networks, 10 deterministic episodes an evaluation) but for the horizon: 40k env steps and 20 evaluations, the same
evaluation every 2000 steps as the 20k runs; it writes ``ROOT/maze-car-shipped/``. ``analyze``: those runs read over
all 40k steps and over their first 20k, each with ``rliable``'s statistics (:mod:`sb3_pilot.experiments.statistics`)
and the ratio of the IQM steps to 90% (HER+PILoT over SAC+HER) with its stratified-bootstrap 95% interval. From the
repository root::

    OMP_NUM_THREADS=1 python -m benchmarks.maze_car_horizon run --seeds 10 --jobs 2 --root zoo_runs/maze-car-horizon
    python -m benchmarks.maze_car_horizon analyze --root zoo_runs/maze-car-horizon > zoo_runs/maze-car-horizon/analysis.md
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

from sb3_pilot.experiments.challenges import BUDGETS, REUSE_SHIPPED, Budget, only_stages, run_challenge
from sb3_pilot.experiments.statistics import compare, first_steps, method_statistics, run_scores
from sb3_pilot.experiments.statistics import format_estimate as fmt

STEPS = 40_000
EVAL_EVERY = 2_000  # the cpu budget's grid (20k steps, 10 evaluations)
WINDOWS = (40_000, 20_000)
PILOT, HER = "HER+PILoT (bonus, displacement_cosine)", "SAC+HER (scratch)"


def budget_40k() -> Budget:
    """The ``cpu`` budget with 20 evaluations: one every 2000 steps over 40k."""
    return dataclasses.replace(BUDGETS["cpu"], name="cpu-40k", n_evals=STEPS // EVAL_EVERY)


def load_runs(root: Path) -> dict[str, list[dict[str, Any]]]:
    """Every method's runs of ``root/maze-car-shipped/summary.json``."""
    path = root / "maze-car-shipped" / "summary.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: run `python -m benchmarks.maze_car_horizon run --root {root}` first")
    return {name: result["runs"] for name, result in json.loads(path.read_text())["methods"].items()}


def method_row(window: int, name: str, runs: list[dict[str, Any]]) -> str:
    """A markdown row: the method's area, steps to 50% / 90% (seeds reaching it within the window) and final success."""
    stats = method_statistics(runs)
    reached = sum(run_scores(r["timesteps"], r["success_rate"])["steps_to_90"] <= window for r in runs)
    return (
        f"{fmt(stats['area'])} | {fmt(stats['steps_to_50'], 0)} | {fmt(stats['steps_to_90'], 0)} ({reached}/{len(runs)}) | "
        f"{fmt(stats['final_success'])} |"
    )


def analyze(root: Path) -> str:
    """The markdown tables of ``analysis.md``."""
    methods = load_runs(root)
    lines = ["| window | method | area | steps to 50% | steps to 90% (seeds) | final success |", "|---|---|---|---|---|---|"]
    comparisons = []
    for last in WINDOWS:
        pilot, her = (first_steps(methods[name], last) for name in (PILOT, HER))
        lines += [
            f"| first {last // 1000}k | {name} | {method_row(last, name, runs)}" for name, runs in ((PILOT, pilot), (HER, her))
        ]
        comparisons.append((last, compare(pilot, her)))
    lines += [
        "",
        "| window | area gain, IQM [95% CI] | P(improvement) | IQM steps to 90%, PILoT / HER [95% CI] | verdict |",
        "|---|---|---|---|---|",
    ]
    for last, result in comparisons:
        lines.append(
            f"| first {last // 1000}k | {fmt(result['area_gain'])} | {fmt(result['probability_of_improvement'])} | "
            f"{fmt(result['steps_to_90_ratio'])} | {result['verdict']} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser("run", help="train both methods for 40k steps")
    run.add_argument("--seeds", type=int, default=10)
    run.add_argument("--jobs", type=int, default=1)
    read = commands.add_parser("analyze", help="print the statistics over 40k and the first 20k steps")
    for command in (run, read):
        command.add_argument("--root", type=Path, required=True, help="the folder of maze-car-shipped/")
    args = parser.parse_args()
    if args.command == "analyze":
        print(analyze(args.root))
        return
    run_challenge(
        only_stages(REUSE_SHIPPED["maze-car"], ["her", "pilot_disp"]),
        budget_40k(),
        seeds=range(args.seeds),
        root=args.root,
        steps={"her": STEPS, "pilot_disp": STEPS},
        jobs=args.jobs,
    )


if __name__ == "__main__":
    main()
