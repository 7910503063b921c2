"""
PointLocomotion's source pair on a fine evaluation grid: UDPO + HER and SAC + HER at the presets
(``hyperparams/cpu/{udpo,sac}.yml``), 80k steps, evaluated every 2000 steps instead of the ``cpu`` budget's 10000, so
that the 1.1x rule on the steps to 90% (about 4.5k steps at SAC + HER's ~43k) is not below the grid's resolution. The
``source-pointlocomotion`` challenge of :mod:`benchmarks.sources` unchanged but for the grid and the steps; it writes
``ROOT/source-pointlocomotion/``. From the repository root::

    OMP_NUM_THREADS=1 python -m benchmarks.pointlocomotion_grid --seeds 0 1 2 3 4 9 \\
        --root zoo_runs/sources/pointlocomotion-grid
    python -m benchmarks.sources --table-only --root zoo_runs/sources/pointlocomotion-grid   # the table
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from benchmarks.sources import source_challenge
from sb3_pilot.experiments.challenges import BUDGETS, run_challenge

STEPS = 80_000
EVAL_EVERY = 2_000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(10)))
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--root", type=Path, required=True, help="the folder of source-pointlocomotion/")
    args = parser.parse_args()
    run_challenge(
        source_challenge("Pilot/PointLocomotion-v0"),
        dataclasses.replace(BUDGETS["cpu"], name="cpu-grid2k", n_evals=STEPS // EVAL_EVERY),
        seeds=args.seeds,
        root=args.root,
        steps={"udpo": STEPS, "her": STEPS},
        jobs=args.jobs,
    )


if __name__ == "__main__":
    main()
