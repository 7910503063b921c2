"""
Does a U-maze teacher go round the wall? A zoo model trained on ``PointMaze_UMaze-v3`` (e.g. the ``teacher`` stage of
``pointmaze-to-antmaze``) run from the U's far start cell to its far goal cell (``far_umaze_map``, gymnasium-robotics'
noise on both, the episode ending at the goal), deterministic actions: its success rate and the median of each
episode's furthest x (the wall ends at x = 0.5, the U's turn is beyond it). A planner distilled from the teacher's
steps plans no better than the teacher moves.

Usage::

    python -m benchmarks.umaze_teacher MODEL [--episodes 20] [--max-steps 300 1000]

Prints the command and one markdown row per episode length.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

from sb3_pilot.experiments.challenges.controller import far_umaze_map
from sb3_pilot.experiments.challenges.stages import load_zoo_model
from sb3_pilot.experiments.zoo import register

TASK = "PointMaze_UMaze-v3"


def far_runs(model_path: Path, episodes: int, max_steps: int) -> tuple[float, float]:
    """Success rate and median furthest x of ``episodes`` far-start episodes of at most ``max_steps`` steps."""
    model, vec_normalize = load_zoo_model(model_path, algo="sac")
    env = gym.make(TASK, maze_map=far_umaze_map(), continuing_task=False, max_episode_steps=max_steps)
    successes, furthest = [], []
    for episode in range(episodes):
        observation, _ = env.reset(seed=episode)
        done, xs, info = False, [], {}
        while not done:
            shown = vec_normalize.normalize_obs(observation) if vec_normalize is not None else observation
            action, _ = model.predict(shown, deterministic=True)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            xs.append(float(observation["achieved_goal"][0]))
        successes.append(float(info.get("success", False)))
        furthest.append(max(xs))
    env.close()
    return float(np.mean(successes)), float(np.median(furthest))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.umaze_teacher", description=__doc__)
    parser.add_argument("model", type=Path, help=f"a zoo model trained on {TASK}")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--max-steps", type=int, nargs="+", default=[300, 1000])
    args = parser.parse_args(argv)
    if not args.model.is_file():
        parser.error(f"no model at {args.model}")
    if args.episodes < 1 or min(args.max_steps) < 1:
        parser.error("--episodes and every --max-steps must be at least 1")
    register()
    print("python -m benchmarks.umaze_teacher " + shlex.join(sys.argv[1:] if argv is None else argv))
    print("| episode steps | far start -> far goal success | median furthest x (the wall ends at 0.5) |")
    print("|---|---|---|")
    for max_steps in args.max_steps:
        success, furthest = far_runs(args.model, args.episodes, max_steps)
        print(f"| {max_steps} | {success:.2f} | {furthest:.2f} |")


if __name__ == "__main__":
    main()
