"""
Where does a guided Ant's time go on the U-maze? ``pointmaze-to-antmaze``'s two evaluations of one seed (its chosen
Ant controller on ``AntMaze_UMaze-v5`` from the far start to the far goal, guided by its PointMaze planner and
unguided: the challenge's own ``pilot`` and ``unguided`` stages, the same seeds) re-run with episodes cut at other
lengths than the task's registered 700 steps. Per length: the success rate and mean final distance of both, and for
the guided episodes the median step at which the Ant passes each part of the U (the top wall's end, x > 2; the bottom
corridor, y < -2; that corridor's far half, x < 0) and the share of episodes that get there. Success that grows with
the length says the guided Ant is on its way but slow, not lost. And how the failed guided episodes end: the Ant on
its back, tilted past 60 degrees, or upright.

Usage::

    python -m benchmarks.umaze_guidance zoo_runs/pointmaze-to-antmaze/models/seed_0 [--max-steps 700 1000 1500]
        [--episodes 30]
    python -m benchmarks.umaze_guidance zoo_runs/pointmaze-to-antmaze-hrl/models/seed_0 --variant hrl --max-steps 700

Prints the command and two markdown tables.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np

from sb3_pilot import LandmarkGuidance
from sb3_pilot.envs import ant_up_z
from sb3_pilot.experiments.challenges import BUDGETS, CHALLENGES, Challenge, challenge_variant
from sb3_pilot.experiments.challenges.controller import ControllerEvaluation, reported_success
from sb3_pilot.experiments.challenges.stages import StageContext, load_zoo_model, play_episodes
from sb3_pilot.experiments.zoo import register

CHALLENGE = CHALLENGES["pointmaze-to-antmaze"]
#: The torso's up axis (z component) under which the Ant counts as tilted past 60 degrees (:func:`ant_up_z`).
TILTED = 0.5
#: The parts of the far U in AntMaze_UMaze-v5's coordinates (cells 4 wide; the start at x = -4, y = 4, the goal at
#: x = -4, y = -4, the wall between them up to x = 2), each a test on the Ant's (x, y).
PARTS = {
    "past the wall's end (x > 2)": lambda xy: xy[:, 0] > 2,
    "in the bottom corridor (y < -2)": lambda xy: xy[:, 1] < -2,
    "its far half (y < -2, x < 0)": lambda xy: (xy[:, 1] < -2) & (xy[:, 0] < 0),
}


def evaluation(challenge: Challenge, name: str) -> ControllerEvaluation:
    """The challenge's evaluation stage ``name``."""
    stage = next(stage for stage in challenge.stages if stage.name == name)
    assert isinstance(stage, ControllerEvaluation)
    return stage


def stage_outputs(challenge: Challenge, seed_dir: Path) -> dict[str, Path]:
    """The output files of the seed's ``chosen`` and ``distill`` stages, where the challenge's stages put them."""
    stages = [stage for stage in challenge.stages if stage.name in ("chosen", "distill")]
    return {stage.name: stage.output(seed_dir / stage.name) for stage in stages}


def run(challenge: Challenge, seed_dir: Path, seed: int, name: str, max_steps: int, episodes: int) -> dict[str, object]:
    """
    The evaluation stage ``name`` of the seed in ``seed_dir``, its episodes cut at ``max_steps``.

    :return: success rate, mean final distance, each episode's success and the torso's up axis at its end
        (:func:`ant_up_z`) and, guided, the step each episode first reached each part (None: never)
    """
    stage = evaluation(challenge, name)
    outputs = stage_outputs(challenge, seed_dir)
    ctx = StageContext(seed_dir, seed, BUDGETS["cpu"], {name: max_steps}, {}, outputs)
    controller, vec_normalize = load_zoo_model(outputs[stage.controller], algo=stage.controller_algo)
    env = stage.make_env(ctx)
    successes, distances, reached, up_z = [], [], [], []
    for observation, info in play_episodes(controller, vec_normalize, env, episodes, seed):
        successes.append(reported_success(info))
        up_z.append(ant_up_z(env.unwrapped.ant_env.data.qpos))
        goal = np.asarray(info.get("real_desired_goal", observation["desired_goal"]))
        distances.append(float(np.linalg.norm(observation["achieved_goal"] - goal)))
        if isinstance(env, LandmarkGuidance):
            path = env.episode_achieved_goals
            reached.append({part: (int(np.argmax(test(path))) if test(path).any() else None) for part, test in PARTS.items()})
    env.close()
    return {
        "success": float(np.mean(successes)),
        "distance": float(np.mean(distances)),
        "reached": reached,
        "successes": successes,
        "up_z": up_z,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.umaze_guidance", description=__doc__)
    parser.add_argument("seed_dir", type=Path, help="the challenge's models/seed_<k> (stages chosen and distill)")
    parser.add_argument("--max-steps", type=int, nargs="+", default=[700, 1000, 1500])
    parser.add_argument("--episodes", type=int, default=30)
    parser.add_argument("--variant", default=None, help="the challenge's variant (hrl: the literature's Ant)")
    args = parser.parse_args(argv)
    try:
        challenge = CHALLENGE if args.variant is None else challenge_variant(CHALLENGE.name, args.variant)
    except ValueError as error:
        parser.error(str(error))
    missing = [str(path) for path in stage_outputs(challenge, args.seed_dir).values() if not path.is_file()]
    if missing or not args.seed_dir.name.startswith("seed_"):
        parser.error(f"{args.seed_dir} is not a finished seed of {challenge.name} (models/seed_<k>): missing {missing}")
    if args.episodes < 1 or min(args.max_steps) < 1:
        parser.error("--episodes and every --max-steps must be at least 1")
    seed = int(args.seed_dir.name.removeprefix("seed_"))
    register()
    print("python -m benchmarks.umaze_guidance " + shlex.join(sys.argv[1:] if argv is None else argv))
    rows, progress, ends = [], [], []
    for max_steps in args.max_steps:
        guided = run(challenge, args.seed_dir, seed, "pilot", max_steps, args.episodes)
        unguided = run(challenge, args.seed_dir, seed, "unguided", max_steps, args.episodes)
        failed = [z for z, success in zip(guided["up_z"], guided["successes"], strict=True) if not success]
        back, tilted = sum(z < 0 for z in failed), sum(0 <= z < TILTED for z in failed)
        ends.append(f"| {max_steps} | {len(failed)} | {back} | {tilted} | {len(failed) - back - tilted} |")
        rows.append(
            f"| {max_steps} | {guided['success']:.2f} | {guided['distance']:.2f} | {unguided['success']:.2f} | "
            f"{unguided['distance']:.2f} |"
        )
        cells = []
        for part in PARTS:
            steps = [episode[part] for episode in guided["reached"] if episode[part] is not None]  # type: ignore[union-attr]
            median = f"{np.median(steps):.0f}" if steps else "-"
            cells.append(f"{len(steps) / args.episodes:.2f} (step {median})")
        progress.append(f"| {max_steps} | " + " | ".join(cells) + " |")
    print(f"\nseed {seed}, {args.episodes} episodes each, far start -> far goal of AntMaze_UMaze-v5 (registered: 700 steps)")
    print("| episode steps | guided success | guided final distance | unguided success | unguided final distance |")
    print("|---|---|---|---|---|")
    print("\n".join(rows))
    print("\nguided episodes reaching each part of the U (share, median first step)")
    print("| episode steps | " + " | ".join(PARTS) + " |")
    print("|---|" + "---|" * len(PARTS))
    print("\n".join(progress))
    print("\nhow the failed guided episodes end")
    print("| episode steps | failed | on its back | tilted past 60 degrees | upright |")
    print("|---|---|---|---|---|")
    print("\n".join(ends))


if __name__ == "__main__":
    main()
