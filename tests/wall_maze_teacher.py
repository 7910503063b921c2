"""
Does a teacher learn to go around the wall of ``WallMazeEnv`` (the xfail in test_distill.py)? UDPO (the test's
``train_udpo`` settings) and SAC + HER with the same settings, then the cross-wall goals each reaches from four
start/goal pairs below the gap: deterministic actions once, sampled actions 5 times. Usage (repository root)::

    OMP_NUM_THREADS=1 python tests/wall_maze_teacher.py --steps 6000 [--step-size 0.2] [--gap-y 0.0] [--no-sac]
"""

import argparse
import functools

import torch as th
from maze_envs import SMALL_HER_SETTINGS, WallMazeEnv, train_udpo
from stable_baselines3 import SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.monitor import Monitor

PAIRS = [((-0.5, -0.6), (0.5, -0.6)), ((0.5, -0.6), (-0.5, -0.6)), ((-0.5, -0.3), (0.6, -0.8)), ((-0.7, -0.8), (0.3, -0.5))]


def cross_wall_successes(model: BaseAlgorithm, env: WallMazeEnv, deterministic: bool, repeats: int) -> int:
    """
    :param model: the trained teacher
    :param env: the maze
    :param deterministic: act with the policy's mean
    :param repeats: passes over the four pairs
    :return: how many episodes reached their goal
    """
    wins = 0
    for repeat in range(repeats):
        for start, goal in PAIRS:
            obs, _ = env.reset(seed=repeat, options={"start": start, "goal": goal})
            for _ in range(env.max_episode_steps):
                obs, _, _, _, info = env.step(model.predict(obs, deterministic=deterministic)[0])
                if info["is_success"]:
                    wins += 1
                    break
    return wins


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--step-size", type=float, default=0.2)
    parser.add_argument("--gap-y", type=float, default=0.0, help="the wall covers y < gap_y")
    parser.add_argument("--no-sac", action="store_true")
    args = parser.parse_args()
    th.set_num_threads(1)
    env_class = functools.partial(WallMazeEnv, step_size=args.step_size, gap_y=args.gap_y)
    models = {"UDPO": train_udpo(env_class, total_timesteps=args.steps)}
    if not args.no_sac:
        models["SAC+HER"] = SAC("MultiInputPolicy", Monitor(env_class()), **SMALL_HER_SETTINGS, seed=0).learn(args.steps)
    for name, model in models.items():
        deterministic = cross_wall_successes(model, env_class(), True, 1)
        sampled = cross_wall_successes(model, env_class(), False, 5)
        print(
            f"{name}, {args.steps} steps, step_size {args.step_size}, gap_y {args.gap_y}: cross-wall goals reached "
            f"{deterministic}/4 deterministic, {sampled}/20 sampled",
            flush=True,
        )


if __name__ == "__main__":
    main()
