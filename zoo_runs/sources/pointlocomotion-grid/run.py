"""
PointLocomotion's source pair on a fine evaluation grid (issue 21): UDPO + HER and SAC + HER at today's presets
(``hyperparams/cpu/{udpo,sac}.yml``: UDPO lambda 1e-3, Delta 1500), 80k steps, evaluated every 2000 steps instead of
the `cpu` budget's 10000, so that the 1.1x rule on the steps to 90% (about 4.5k steps at HER's ~43k) is not below
the grid's resolution. The `source-pointlocomotion` challenge unchanged but for the grid and the steps. Writes
``zoo_runs/sources/pointlocomotion-grid/source-pointlocomotion/``; the seeds run in order (both methods of a seed
before the next), so a stopped run keeps whole seeds.

    OMP_NUM_THREADS=1 python zoo_runs/sources/pointlocomotion-grid/run.py --seeds 10 --jobs 1
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from sb3_pilot.experiments.benchmarks.sources import source_challenge
from sb3_pilot.experiments.challenges.definitions import BUDGETS
from sb3_pilot.experiments.challenges.runner import run_challenge

STEPS = 80_000
EVAL_EVERY = 2_000

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--jobs", type=int, default=1)
    args = parser.parse_args()
    budget = dataclasses.replace(BUDGETS["cpu"], name="cpu-grid2k", n_evals=STEPS // EVAL_EVERY)
    run_challenge(
        source_challenge("Pilot/PointLocomotion-v0"),
        budget,
        seeds=range(args.seeds),
        root=Path(__file__).parent,
        steps={"udpo": STEPS, "her": STEPS},
        jobs=args.jobs,
    )
