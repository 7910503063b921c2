"""
The paper's High-Dim-Action challenge on Fetch-Reach: a source UDPO on Pilot/FetchReach-v0, then, on
Pilot/FetchReachHighDim-v0 (8-dim actions, other action dynamics, 80% gravity), a target UDPO with the transferred,
frozen state planner (only its inverse dynamics learns) against SAC + HER from scratch. Success vs env steps.

    OMP_NUM_THREADS=1 python -m benchmarks.high_dim_transfer \
        --source-steps 5000 --steps 5000 --seeds 0 1 2

All models use RL-Zoo's FetchReach settings (64x64 nets, VecNormalize, gamma 0.95, lr 1e-3, batch 256, HER);
the target carries the source's VecNormalize statistics (frozen with the planner).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

from sb3_pilot.envs import register_envs
from sb3_pilot.transfer import load_planner_from
from sb3_pilot.udpo import UDPO

SOURCE_ID, TARGET_ID = "Pilot/FetchReach-v0", "Pilot/FetchReachHighDim-v0"


def common_kwargs() -> dict[str, Any]:
    """Fresh settings (SB3 writes into ``policy_kwargs``, so models must not share the dict)."""
    return {
        "replay_buffer_class": HerReplayBuffer,
        "learning_starts": 1000,
        "batch_size": 256,
        "gamma": 0.95,
        "learning_rate": 1e-3,
        "policy_kwargs": {"net_arch": [64, 64]},
    }


UDPO_KWARGS = {"inverse_dynamics_interval": 200, "inverse_dynamics_learning_rate": 1e-3, "inverse_dynamics_gradient_steps": 50}


def success_rate(model: BaseAlgorithm, env_id: str, n_episodes: int) -> float:
    """Final-step success of deterministic episodes, observations scaled by the model's own VecNormalize."""
    env, vec_normalize = gym.make(env_id), model.get_vec_normalize_env()
    successes = []
    for episode in range(n_episodes):
        obs, _ = env.reset(seed=10_000 + episode)
        done = False
        while not done:
            seen = vec_normalize.normalize_obs(obs) if vec_normalize is not None else obs
            action, _ = model.predict(seen, deterministic=True)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes.append(info["is_success"])
    return float(np.mean(successes))


def learning_curve(model: BaseAlgorithm, env_id: str, args: argparse.Namespace) -> list[float]:
    """Success after every ``eval_freq`` training steps."""
    rates = []
    for _ in range(args.steps // args.eval_freq):
        model.learn(args.eval_freq, reset_num_timesteps=False)
        rates.append(success_rate(model, env_id, args.eval_episodes))
    return rates


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--source-steps", type=int, default=5000)
    parser.add_argument("--steps", type=int, default=5000, help="env steps of each target run")
    parser.add_argument("--eval-freq", type=int, default=1000)
    parser.add_argument("--eval-episodes", type=int, default=10)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = parser.parse_args()
    register_envs()

    start = time.perf_counter()
    results: dict[str, list[list[float]]] = {"pilot_transfer": [], "sac_her": []}
    for seed in args.seeds:
        source_env = VecNormalize(make_vec_env(SOURCE_ID, seed=seed), norm_reward=False)
        source = UDPO("MultiInputPolicy", source_env, seed=seed, **common_kwargs(), **UDPO_KWARGS)
        source.learn(args.source_steps)
        print(f"seed {seed}: source UDPO success {success_rate(source, SOURCE_ID, args.eval_episodes):.2f}", flush=True)
        target = load_planner_from(source, gym.make(TARGET_ID), seed=seed, **common_kwargs(), **UDPO_KWARGS)
        results["pilot_transfer"].append(learning_curve(target, TARGET_ID, args))
        scratch_env = VecNormalize(make_vec_env(TARGET_ID, seed=seed), norm_reward=False)
        results["sac_her"].append(
            learning_curve(SAC("MultiInputPolicy", scratch_env, seed=seed, **common_kwargs()), TARGET_ID, args)
        )
        print(f"seed {seed}: { ({name: curves[-1] for name, curves in results.items()}) }", flush=True)

    steps = [args.eval_freq * (i + 1) for i in range(args.steps // args.eval_freq)]
    print(f"\n{TARGET_ID}: success rate (mean [min, max] over seeds {args.seeds}) vs env steps")
    print("| method | " + " | ".join(str(step) for step in steps) + " |")
    print("|---|" + "---|" * len(steps))
    for name, curves in results.items():
        rates = np.array(curves)
        cells = [
            f"{mean:.2f} [{low:.1f}, {high:.1f}]"
            for mean, low, high in zip(rates.mean(0), rates.min(0), rates.max(0), strict=True)
        ]
        print(f"| {name} | " + " | ".join(cells) + " |")
    print(f"\n({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
