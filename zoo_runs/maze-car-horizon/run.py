"""
Maze-Car past its budget: SAC+HER and HER+PILoT (displacement cosine) for 40k steps instead of the committed 20k,
to measure steps to 90% where SAC+HER's are censored at 20k on 8 of 10 seeds (issue 20).

The `maze-car --reuse-shipped` challenge unchanged (the shipped Maze2D planner, the cpu budget's 64x64 networks,
10 deterministic episodes an evaluation) but for the horizon: 40k env steps and 20 evaluations, i.e. the same
evaluation every 2000 steps as the committed 20k runs. Writes ``zoo_runs/maze-car-horizon/maze-car-shipped/``.

    OMP_NUM_THREADS=1 python zoo_runs/maze-car-horizon/run.py --seeds 10 --jobs 1
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from sb3_pilot.experiments.challenges.definitions import BUDGETS, REUSE_SHIPPED, only_stages
from sb3_pilot.experiments.challenges.runner import run_challenge

STEPS = 40_000
EVAL_EVERY = 2_000  # the committed cpu budget's grid (20k steps, 10 evaluations)

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    budget = dataclasses.replace(BUDGETS["cpu"], name="cpu-40k", n_evals=STEPS // EVAL_EVERY)
    challenge = only_stages(REUSE_SHIPPED["maze-car"], ["her", "pilot_disp"])
    run_challenge(
        challenge,
        budget,
        seeds=range(args.seeds),
        root=Path(__file__).parent,
        steps={"her": STEPS, "pilot_disp": STEPS},
        jobs=args.jobs,
    )
