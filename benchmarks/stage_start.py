"""
Cost of starting a challenge's stages: each forked from the preloaded fork server (the default) against each a fresh
interpreter (``spawn``: what every stage paid before, and what a platform without a fork server still pays).

A smoke-budget challenge (tiny stages, so start-up is most of their time) runs ``--rounds`` times with each start
method, alternating (so machine load hits both alike), each in a fresh folder, one stage at a time, in one process
whose fork server is already running (as in any run after its first stage). It prints the wall time of each run, the
sum of the stages' own times (``wall_time_s``: the work, not the start-up), and the ratio of the medians.

    OMP_NUM_THREADS=1 MUJOCO_GL=osmesa python -m benchmarks.stage_start --challenge maze-car --rounds 2
"""

from __future__ import annotations

import argparse
import multiprocessing
import statistics
import tempfile
import time
from pathlib import Path
from unittest import mock

from sb3_pilot.experiments.challenges import backends, run_challenge


def timed_run(challenge: str, spawn: bool) -> tuple[float, float, int]:
    """
    One smoke-budget run of ``challenge`` in a fresh folder.

    :param spawn: start each stage in a fresh interpreter instead of forking it from the server
    :return: its wall time, the sum of its stages' own times and its number of stages
    """
    with tempfile.TemporaryDirectory() as root:
        start = time.perf_counter()
        if spawn:
            with mock.patch.object(backends, "_context", lambda: multiprocessing.get_context("spawn")):
                summary = run_challenge(challenge, "smoke", seeds=[0], root=Path(root))
        else:
            summary = run_challenge(challenge, "smoke", seeds=[0], root=Path(root))
        wall = time.perf_counter() - start
    stages = summary["stages"].values()
    return wall, sum(stage["wall_time_s"] for stage in stages), len(stages)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--challenge", default="maze-car", help="a challenge with a smoke budget")
    parser.add_argument("--rounds", type=int, default=2, help="runs with each start method")
    args = parser.parse_args()
    timed_run(args.challenge, spawn=False)  # starts the fork server (once per process), not timed
    walls: dict[str, list[float]] = {"fork server": [], "fresh interpreter": []}
    for round_ in range(args.rounds):
        for name in walls:
            wall, work, n = timed_run(args.challenge, spawn=name == "fresh interpreter")
            walls[name].append(wall)
            print(f"round {round_}: {name:17s} {n} stages, wall {wall:6.1f} s, stages' own time {work:5.1f} s")
    fork, fresh = (statistics.median(walls[name]) for name in ("fork server", "fresh interpreter"))
    print(f"median wall: fork server {fork:.1f} s, fresh interpreter {fresh:.1f} s, ratio {fresh / fork:.2f}x")
    print(f"command: python -m benchmarks.stage_start --challenge {args.challenge} --rounds {args.rounds}")


if __name__ == "__main__":
    main()
