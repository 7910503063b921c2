"""
Maze-Car with the ``planned_progress`` bonus, and with exact landmarks: HER+PILoT with the bonus of how far the car
advances along the planned move, against SAC+HER, for 40k steps as :mod:`benchmarks.maze_car_horizon`.

``run``: the ``maze-car --reuse-shipped`` challenge (the shipped Maze2D planner, the ``cpu`` budget's 64x64 networks,
10 deterministic episodes every 2000 steps) for 40k env steps, with its ``her`` stage, a ``pilot_prog`` stage
(``pilot_disp``'s with ``similarity: planned_progress``) and an ``oracle_prog`` stage: the same with exact landmarks
(:class:`~benchmarks.oracle_landmarks.OracleBonusWrapper`: a step of the U-maze's shortest path) instead of the
planner's, the best a landmark could do. It writes ``ROOT/maze-car-shipped/``. ``analyze``: those runs beside the
displacement-cosine runs of :mod:`benchmarks.maze_car_horizon` (same setup, same seeds), over all 40k steps and over
their first 20k, each method against SAC+HER and the ``planned_progress`` bonus against the displacement cosine. From
the repository root::

    OMP_NUM_THREADS=1 python -m benchmarks.maze_car_progress run --seeds 10 --jobs 2 --root zoo_runs/maze-car-progress
    python -m benchmarks.maze_car_progress analyze --root zoo_runs/maze-car-progress \\
        --horizon zoo_runs/maze-car-horizon > zoo_runs/maze-car-progress/analysis.md
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

from benchmarks.maze_car_horizon import STEPS, WINDOWS, budget_40k, load_runs, method_row
from benchmarks.oracle_landmarks import OracleBonusWrapper
from sb3_pilot.experiments.challenges import REUSE_SHIPPED, only_stages, run_challenge
from sb3_pilot.experiments.challenges.definitions import bonus_params
from sb3_pilot.experiments.statistics import compare, first_steps
from sb3_pilot.experiments.statistics import format_estimate as fmt

HER, DISPLACEMENT = "SAC+HER (scratch)", "HER+PILoT (bonus, displacement_cosine)"
PROGRESS, ORACLE = "HER+PILoT (bonus, planned_progress)", "HER+exact landmarks (bonus, planned_progress)"
#: (method, baseline) pairs compared, on the area under the success curve and the steps to 90%
COMPARISONS = ((DISPLACEMENT, HER), (PROGRESS, HER), (ORACLE, HER), (PROGRESS, DISPLACEMENT), (ORACLE, PROGRESS))


def oracle_bonus(outputs: dict[str, Path]) -> dict[str, Any]:
    """``-params`` of the ``oracle_prog`` stage: the bonus of exact landmarks."""
    kwargs = {"beta": 1.0, "similarity": "planned_progress"}
    return {"env_wrapper": [{f"{OracleBonusWrapper.__module__}.{OracleBonusWrapper.__qualname__}": kwargs}]}


def load_methods(root: Path, horizon: Path) -> tuple[dict[str, list[dict[str, Any]]], str]:
    """The runs of every method, the displacement cosine's from ``horizon`` for the same seeds; and a line saying
    whether SAC+HER's runs here are those of ``horizon``."""
    methods, earlier = load_runs(root), load_runs(horizon)
    seeds = [run["seed"] for run in methods[HER]]
    curves = {run["seed"]: run["success_rate"] for run in earlier[HER]}
    same = sum(run["success_rate"] == curves.get(run["seed"]) for run in methods[HER])
    methods[DISPLACEMENT] = [run for run in earlier[DISPLACEMENT] if run["seed"] in seeds]
    return methods, f"SAC+HER here and in ../{horizon.name}: identical curves on {same} of {len(seeds)} seeds"


def analyze(root: Path, horizon: Path) -> str:
    """The markdown tables of ``analysis.md``."""
    methods, check = load_methods(root, horizon)
    lines = [
        check,
        "",
        "| window | method | seeds | area | steps to 50% | steps to 90% (seeds reaching it) | final success |",
        "|---|---|---|---|---|---|---|",
    ]
    windows = {last: {name: first_steps(runs, last) for name, runs in methods.items()} for last in WINDOWS}
    for last, window in windows.items():
        lines += [
            f"| first {last // 1000}k | {name} | {len(runs)} | {method_row(last, name, runs)}" for name, runs in window.items()
        ]
    lines += [
        "",
        "| window | method | against | area gain, IQM [95% CI] | P(improvement) | IQM steps to 90%, ratio [95% CI] "
        "| verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    for last, window in windows.items():
        for method, baseline in (pair for pair in COMPARISONS if set(pair) <= set(window)):
            result = compare(window[method], window[baseline])
            ratio = fmt(result["steps_to_90_ratio"]) if result["steps_to_90_ratio"] else "-"
            lines.append(
                f"| first {last // 1000}k | {method} | {baseline} | {fmt(result['area_gain'])} | "
                f"{fmt(result['probability_of_improvement'])} | {ratio} | {result['verdict']} |"
            )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser("run", help="train SAC+HER, the progress bonus and exact landmarks for 40k steps")
    run.add_argument("--seeds", type=int, default=10)
    run.add_argument("--first-seed", type=int, default=0)
    run.add_argument("--jobs", type=int, default=1)
    read = commands.add_parser("analyze", help="print the statistics over 40k and the first 20k steps")
    read.add_argument("--horizon", type=Path, required=True, help="maze_car_horizon's --root (the displacement cosine)")
    for command in (run, read):
        command.add_argument("--root", type=Path, required=True, help="the folder of maze-car-shipped/")
    args = parser.parse_args()
    if args.command == "analyze":
        print(analyze(args.root, args.horizon))
        return
    challenge = only_stages(REUSE_SHIPPED["maze-car"], ["her", "pilot_disp"])
    stages = {stage.name: stage for stage in challenge.stages}
    progress = dataclasses.replace(
        stages["pilot_disp"], name="pilot_prog", params=bonus_params("distill", "planned_progress"), method=PROGRESS
    )
    oracle = dataclasses.replace(stages["pilot_disp"], name="oracle_prog", params=oracle_bonus, needs=(), method=ORACLE)
    run_challenge(
        dataclasses.replace(challenge, stages=(stages["distill"], stages["her"], progress, oracle)),
        budget_40k(),
        seeds=range(args.first_seed, args.first_seed + args.seeds),
        root=args.root,
        steps={"her": STEPS, "pilot_prog": STEPS, "oracle_prog": STEPS},
        jobs=args.jobs,
    )


if __name__ == "__main__":
    main()
