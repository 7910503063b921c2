"""
How far ahead of the agent is the ``k``-th landmark? The lead ``||plan(g, g_target, k)[-1] - g||`` of a U-maze goal
planner's chained, unsnapped landmarks (what :class:`~sb3_pilot.LandmarkGuidance` shows a controller at horizon
``k``), from starts at the U's far end towards goals at its other end (gymnasium-robotics' noise on both), in the
target task's units: the planner's goals times ``--scale`` (4 for a ``PointMaze_UMaze-v3`` planner guiding on
``AntMaze_UMaze-v5``, 1 for a ``Pilot/Maze2D-v0`` planner on ``Pilot/AntMaze-v0``, which share AntMaze's coordinates).

A controller trained on goals a given distance away is guided best by landmarks about that far ahead: the horizon of
one planner can be set from another's by matching leads rather than ``k`` (planners of tasks with other step lengths
need other ``k``).

Usage::

    python -m benchmarks.landmark_lead PLANNER [PLANNER ...] --scale 4 --horizons 1 2 3 5 10 15 20

Prints the command and a markdown table: per planner, the median lead (and its 25-75% range over 100 start/goal
pairs) at each horizon, and the first step's median length.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np

from sb3_pilot import GoalPlanner
from sb3_pilot.envs import UMAZE_SCALING, sample_umaze_start_goal


def far_pairs(n: int, scale: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """
    ``n`` starts and goals at the U-maze's two far ends (``sample_umaze_start_goal``, with gymnasium-robotics' noise),
    in the planner's coordinates (AntMaze's divided by ``scale``).
    """
    rng = np.random.default_rng(seed)
    starts, goals = zip(*(sample_umaze_start_goal(rng, "far") for _ in range(n)), strict=True)
    return np.array(starts) / scale, np.array(goals) / scale


def leads(planner: GoalPlanner, horizons: list[int], scale: float, n: int = 100) -> dict[str, list[float]]:
    """
    The lead of the chained landmarks at each horizon, in the target's units.

    :param planner: a goal planner of a U-maze task
    :param horizons: the horizons ``k``
    :param scale: target units per planner unit
    :param n: start/goal pairs
    :return: ``{"median", "q25", "q75"}`` per horizon, and ``first_step`` (one-element list)
    """
    starts, goals = far_pairs(n, scale)
    path = planner.plan(starts, goals, horizon=max(horizons), snap=False)
    lead = scale * np.linalg.norm(path - starts[:, None], axis=-1)
    chosen = lead[:, np.array(horizons) - 1]
    return {
        "median": np.median(chosen, axis=0).tolist(),
        "q25": np.quantile(chosen, 0.25, axis=0).tolist(),
        "q75": np.quantile(chosen, 0.75, axis=0).tolist(),
        "first_step": [float(np.median(lead[:, 0]))],
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.landmark_lead", description=__doc__)
    parser.add_argument("planners", nargs="+", type=Path, help="goal planner files (planner.pt)")
    parser.add_argument("--scale", type=float, default=1.0, help="target units per planner unit (4: PointMaze -> AntMaze)")
    parser.add_argument("--horizons", type=int, nargs="+", default=[1, 2, 3, 5, 10, 15, 20])
    parser.add_argument("--pairs", type=int, default=100, help="start/goal pairs")
    args = parser.parse_args(argv)
    if args.scale <= 0 or args.pairs < 1 or min(args.horizons) < 1:
        parser.error("--scale must be positive, --pairs and every horizon at least 1")
    missing = [str(path) for path in args.planners if not path.is_file()]
    if missing:
        parser.error(f"no planner file at {', '.join(missing)}")
    print("python -m benchmarks.landmark_lead " + shlex.join(sys.argv[1:] if argv is None else argv))
    print(
        f"\nlead of the k-th chained landmark (target units; the U-maze's cells are {UMAZE_SCALING:g} wide), median [25%, 75%]"
    )
    print("| planner | first step | " + " | ".join(f"k = {k}" for k in args.horizons) + " |")
    print("|---|---|" + "---|" * len(args.horizons))
    for path in args.planners:
        result = leads(GoalPlanner.load(path), args.horizons, args.scale, args.pairs)
        cells = (f"{m:.2f} [{a:.2f}, {b:.2f}]" for m, a, b in zip(result["median"], result["q25"], result["q75"], strict=True))
        print(f"| {path} | {result['first_step'][0]:.3f} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
