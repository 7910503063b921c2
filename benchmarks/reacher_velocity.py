"""
Does Reacher need its velocities? A pixel agent's single frame shows where the arm is, not how fast it moves. This
trains SAC + HER on the vector ``Pilot/Reacher-v0`` with the ``cpu/sac.yml`` preset, with the observation as it is
and with the joint velocities zeroed (all else equal, same seeds), and evaluates each every ``--eval-freq`` steps on
``--eval-episodes`` deterministic episodes. If the velocity-blind agent learns far later (or not), a frame stack (or
another source of velocity) belongs in the pixel recipe; if it learns as fast, the pixel agents' gap lies elsewhere.

Usage::

    OMP_NUM_THREADS=1 python -m benchmarks.reacher_velocity [--steps 30000] [--eval-freq 5000] [--eval-episodes 20]
        [--seeds 0] [--variants full blind]

Prints the command and a markdown table: success rate at each evaluation, per variant and seed.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from typing import Any

import gymnasium as gym
import numpy as np
import yaml
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.env_util import make_vec_env

from sb3_pilot.envs import register_envs
from sb3_pilot.experiments.zoo import hyperparams_dir

TASK = "Pilot/Reacher-v0"
#: The entries of ``Pilot/Reacher-v0``'s observation that hold the joint velocities (cos q, sin q, qdot, fingertip).
VELOCITIES = slice(6, 9)


class ZeroVelocity(gym.ObservationWrapper):
    """``Pilot/Reacher-v0`` with the joint velocities of its ``observation`` entry set to 0 (the goals untouched)."""

    def observation(self, observation: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        blind = observation["observation"].copy()
        blind[VELOCITIES] = 0.0
        return {**observation, "observation": blind}


def preset() -> tuple[dict[str, Any], dict[str, Any]]:
    """SAC's arguments from the task's ``cpu/sac.yml`` entry (its HER buffer included), and the entry."""
    entry = yaml.safe_load((hyperparams_dir() / "cpu" / "sac.yml").read_text())[TASK]
    kwargs = {key: entry[key] for key in ("gamma", "buffer_size", "batch_size", "learning_starts", "learning_rate")}
    return dict(kwargs, replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=eval(entry["replay_buffer_kwargs"])), entry


def success_rate(model: SAC, blind: bool, episodes: int, seed: int) -> float:
    """Deterministic episodes of the task: the share that ends in success."""
    env = gym.make(TASK)
    env = ZeroVelocity(env) if blind else env
    successes = 0
    for episode in range(episodes):
        observation, _ = env.reset(seed=1_000_000 + 1000 * seed + episode)
        done, info = False, {}
        while not done:
            action, _ = model.predict(observation, deterministic=True)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes += bool(info.get("is_success", False))
    env.close()
    return successes / episodes


def run(variant: str, seed: int, steps: int, eval_freq: int, eval_episodes: int) -> tuple[list[float], float]:
    """One SAC + HER run; its success rates at each evaluation and its wall seconds."""
    kwargs, entry = preset()
    blind = variant == "blind"
    env = make_vec_env(TASK, n_envs=int(entry["n_envs"]), seed=seed, wrapper_class=ZeroVelocity if blind else None)
    model = SAC("MultiInputPolicy", env, seed=seed, device="cpu", **kwargs)
    rates, start = [], time.perf_counter()
    for _ in range(steps // eval_freq):
        model.learn(eval_freq, reset_num_timesteps=False)
        rates.append(success_rate(model, blind, eval_episodes, seed))
        print(f"{variant} seed {seed}: {model.num_timesteps} steps, success {rates[-1]:.2f}", flush=True)
    return rates, time.perf_counter() - start


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.reacher_velocity", description=__doc__)
    parser.add_argument("--steps", type=int, default=30_000)
    parser.add_argument("--eval-freq", type=int, default=5000)
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--variants", nargs="+", choices=["full", "blind"], default=["full", "blind"])
    args = parser.parse_args(argv)
    if args.eval_freq < 1 or args.steps < args.eval_freq or args.eval_episodes < 1:
        parser.error("--eval-freq and --eval-episodes must be positive and --steps at least --eval-freq")
    register_envs()
    command = "python -m benchmarks.reacher_velocity " + shlex.join(sys.argv[1:] if argv is None else argv)
    print(command)
    rows = []
    for variant in args.variants:
        for seed in args.seeds:
            rates, seconds = run(variant, seed, args.steps, args.eval_freq, args.eval_episodes)
            rows.append(f"| {variant} | {seed} | " + " | ".join(f"{rate:.2f}" for rate in rates) + f" | {seconds:.0f} |")
    steps = range(args.eval_freq, args.eval_freq * (args.steps // args.eval_freq) + 1, args.eval_freq)
    print(f"\n{command}\n")
    print("| observation | seed | " + " | ".join(f"success at {step}" for step in steps) + " | seconds |")
    print("|---|---|" + "---|" * (len(steps) + 1))
    print("\n".join(rows))


if __name__ == "__main__":
    main()
