"""
Maze-Car with the ``planned_progress`` bonus: HER+PILoT with the bonus of how far the car advances along the planned
move, against SAC+HER, 40k steps, the Maze-Car horizon run's setup otherwise (issue 20, item 4).

The `maze-car --reuse-shipped` challenge (the shipped Maze2D planner, the cpu budget's 64x64 networks, 10
deterministic episodes every 2000 steps) for 40k env steps, as ``zoo_runs/maze-car-horizon``, with its ``her`` stage
a ``pilot_prog`` stage: ``pilot_disp``'s stage with ``similarity: planned_progress``, and an ``oracle_prog`` stage: the
same with exact landmarks (``OracleBonusWrapper``: a step of the U-maze's shortest path) instead of the planner's,
the best a landmark could do. Writes ``zoo_runs/maze-car-progress/maze-car-shipped/``.

    OMP_NUM_THREADS=1 python zoo_runs/maze-car-progress/run.py --seeds 10 --jobs 1
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any

from sb3_pilot.experiments.benchmarks.oracle_landmarks import OracleBonusWrapper
from sb3_pilot.experiments.challenges.definitions import BUDGETS, REUSE_SHIPPED, bonus_params, only_stages
from sb3_pilot.experiments.challenges.runner import run_challenge

STEPS = 40_000
EVAL_EVERY = 2_000  # the committed cpu budget's grid (20k steps, 10 evaluations)
PROGRESS = "HER+PILoT (bonus, planned_progress)"
ORACLE = "HER+exact landmarks (bonus, planned_progress)"


def oracle_bonus(outputs: dict[str, Path]) -> dict[str, Any]:
    """``-params`` of the ``oracle_prog`` stage: the bonus of exact landmarks."""
    kwargs = {"beta": 1.0, "similarity": "planned_progress"}
    return {"env_wrapper": [{f"{OracleBonusWrapper.__module__}.{OracleBonusWrapper.__qualname__}": kwargs}]}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    budget = dataclasses.replace(BUDGETS["cpu"], name="cpu-40k", n_evals=STEPS // EVAL_EVERY)
    challenge = only_stages(REUSE_SHIPPED["maze-car"], ["her", "pilot_disp"])
    stages = {stage.name: stage for stage in challenge.stages}
    progress = dataclasses.replace(
        stages["pilot_disp"], name="pilot_prog", params=bonus_params("distill", "planned_progress"), method=PROGRESS
    )
    oracle = dataclasses.replace(stages["pilot_disp"], name="oracle_prog", params=oracle_bonus, needs=(), method=ORACLE)
    challenge = dataclasses.replace(challenge, stages=(stages["distill"], stages["her"], progress, oracle))
    run_challenge(
        challenge,
        budget,
        seeds=range(args.first_seed, args.first_seed + args.seeds),
        root=Path(__file__).parent,
        steps={"her": STEPS, "pilot_prog": STEPS, "oracle_prog": STEPS},
        jobs=args.jobs,
    )
