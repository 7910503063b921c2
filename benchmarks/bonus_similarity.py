"""
Which similarity should PilotBonusWrapper use? Success vs env steps of SAC + HER on a maze whose goal origin lies
inside the workspace (Pilot/Maze2D-v0: the origin is the U-maze's central wall), without bonus and with the bonus
of each similarity, from one goal planner distilled from a UDPO source trained on the same maze.

    OMP_NUM_THREADS=1 python -m benchmarks.bonus_similarity \
        --source-steps 10000 --steps 10000 --seeds 0 1

Success is that of the final step of deterministic evaluation episodes (the env's ``is_success``).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.base_class import BaseAlgorithm

from sb3_pilot.distill import GoalPlanner, distill_goal_planner
from sb3_pilot.envs import register_envs
from sb3_pilot.transfer import SIMILARITIES, PilotBonusWrapper, PilotHerReplayBuffer
from sb3_pilot.udpo import UDPO

ENV_ID = "Pilot/Maze2D-v0"


# Small RL-Zoo-like settings shared by the source and the targets
def common_kwargs() -> dict[str, Any]:
    """Fresh settings (SB3 writes into ``policy_kwargs``, so models must not share the dict)."""
    return {
        "learning_starts": 1000,
        "batch_size": 256,
        "gamma": 0.95,
        "learning_rate": 1e-3,
        "policy_kwargs": {"net_arch": [64, 64]},
    }


def success_rate(model: BaseAlgorithm, env: gym.Env, n_episodes: int, seed: int) -> float:
    """Share of deterministic episodes whose final step is a success."""
    successes = []
    for episode in range(n_episodes):
        obs, _ = env.reset(seed=seed + episode)
        done = False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes.append(info["is_success"])
    return float(np.mean(successes))


def train_source(steps: int, goal_distribution: str, seed: int) -> GoalPlanner:
    """UDPO + HER on the maze, distilled into a goal planner."""
    model = UDPO(
        "MultiInputPolicy",
        gym.make(ENV_ID, goal_distribution=goal_distribution),
        replay_buffer_class=HerReplayBuffer,
        inverse_dynamics_interval=200,
        inverse_dynamics_learning_rate=1e-3,
        inverse_dynamics_gradient_steps=50,
        seed=seed,
        **common_kwargs(),
    )
    model.learn(steps)
    eval_env = gym.make(ENV_ID, goal_distribution=goal_distribution)
    print(f"source UDPO: success {success_rate(model, eval_env, 20, 10_000):.2f} after {steps} steps")
    planner = distill_goal_planner(model, net_arch=[64, 64], seed=seed)
    print(f"distillation held-out report: {planner.metadata['holdout']}")
    return planner


def curve(variant: str, planner: GoalPlanner, args: argparse.Namespace, seed: int) -> list[float]:
    """Success after every ``eval_freq`` steps of SAC + HER (with the bonus of ``variant`` unless it is ``her``)."""
    env = gym.make(ENV_ID, goal_distribution=args.goal_distribution)
    buffer_class = HerReplayBuffer
    if variant != "her":
        env, buffer_class = PilotBonusWrapper(env, planner, beta=args.beta, similarity=variant), PilotHerReplayBuffer
    model = SAC("MultiInputPolicy", env, replay_buffer_class=buffer_class, seed=seed, **common_kwargs())
    eval_env = gym.make(ENV_ID, goal_distribution=args.goal_distribution)
    rates = []
    for _ in range(args.steps // args.eval_freq):
        model.learn(args.eval_freq, reset_num_timesteps=False)
        rates.append(success_rate(model, eval_env, args.eval_episodes, 10_000))
    return rates


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--source-steps", type=int, default=10_000, help="UDPO steps on the source maze")
    parser.add_argument("--steps", type=int, default=10_000, help="SAC + HER steps per target run")
    parser.add_argument("--eval-freq", type=int, default=2000)
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--beta", type=float, default=1.0)
    parser.add_argument("--goal-distribution", default="uniform", help="Maze2D goals of the target runs: uniform or far")
    args = parser.parse_args()
    register_envs()

    start = time.perf_counter()
    planner = train_source(args.source_steps, "uniform", seed=0)
    results = {
        variant: np.array([curve(variant, planner, args, seed) for seed in args.seeds]) for variant in ("her", *SIMILARITIES)
    }
    steps = [args.eval_freq * (i + 1) for i in range(args.steps // args.eval_freq)]
    print(f"\nSuccess rate (mean over seeds {args.seeds}, {args.eval_episodes} episodes each) vs env steps")
    print("| variant | " + " | ".join(str(step) for step in steps) + " |")
    print("|---|" + "---|" * len(steps))
    for variant, rates in results.items():
        print(f"| {variant} | " + " | ".join(f"{rate:.2f}" for rate in rates.mean(axis=0)) + " |")
    print(f"\n({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
