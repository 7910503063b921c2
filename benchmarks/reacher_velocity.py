"""
What does SAC + HER need to learn Reacher, before any pixel? A pixel agent's single frame shows where the arm is, not
how fast it moves, and the image preset's RL settings are not those under which the vector sources learn. This trains
SAC + HER on the vector ``Pilot/Reacher-v0`` under a recipe:

- ``source``: the vec-to-image-reacher source's (RL-Zoo's FetchReach settings with VecNormalize, one env: one gradient
  step per env step, gamma 0.95, learning rate 1e-3, batch 256, 64x64 networks);
- ``preset``: the task's ``cpu/sac.yml`` entry (4 envs, one gradient step per vector step, gamma 0.99, learning rate
  3e-4, batch 256, no normalisation), whose RL settings the image preset shares;

with the observation as it is (``full``) or with the joint velocities zeroed (``blind``), all else equal, and
evaluates each every ``--eval-freq`` steps on ``--eval-episodes`` deterministic episodes.

Usage::

    OMP_NUM_THREADS=1 python -m benchmarks.reacher_velocity [--steps 30000] [--eval-freq 5000] [--eval-episodes 20]
        [--seeds 0] [--recipes source preset] [--variants full blind]

Prints the command and a markdown table: success rate at each evaluation, per recipe, variant and seed.
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
from stable_baselines3.common.vec_env import VecEnv, VecNormalize

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


def recipe(name: str) -> tuple[dict[str, Any], int, bool]:
    """SAC's arguments (with the HER buffer), the number of envs and whether VecNormalize applies, of a recipe."""
    her = {
        "replay_buffer_class": HerReplayBuffer,
        "replay_buffer_kwargs": {"goal_selection_strategy": "future", "n_sampled_goal": 4},
    }
    if name == "source":
        recipe = yaml.safe_load((hyperparams_dir() / "cpu" / "reacher" / "sac.yml").read_text())[TASK]
        settings = {key: recipe[key] for key in ("gamma", "learning_rate", "batch_size", "learning_starts")}
        settings["policy_kwargs"] = eval(recipe["policy_kwargs"])  # as the zoo reads it
        return {**settings, **her}, 1, bool(recipe["normalize"])
    entry = yaml.safe_load((hyperparams_dir() / "cpu" / "sac.yml").read_text())[TASK]
    keys = ("gamma", "buffer_size", "batch_size", "learning_starts", "learning_rate")
    assert eval(entry["replay_buffer_kwargs"]) == her["replay_buffer_kwargs"] and "normalize" not in entry
    return {**{key: entry[key] for key in keys}, **her}, int(entry["n_envs"]), False


def success_rate(model: SAC, blind: bool, train_env: VecEnv, episodes: int, seed: int) -> float:
    """Deterministic episodes of the task (through the training env's frozen VecNormalize, if any): the success rate."""
    env: VecEnv = make_vec_env(TASK, n_envs=1, wrapper_class=ZeroVelocity if blind else None)
    if isinstance(train_env, VecNormalize):
        env = VecNormalize(env, training=False, norm_reward=False)
        env.obs_rms = train_env.obs_rms
    successes = 0
    for episode in range(episodes):
        env.seed(1_000_000 + 1000 * seed + episode)
        observation = env.reset()
        done = np.array([False])
        while not done[0]:
            action, _ = model.predict(observation, deterministic=True)
            observation, _, done, infos = env.step(action)
        successes += bool(infos[0].get("is_success", False))
    env.close()
    return successes / episodes


def run(name: str, variant: str, seed: int, steps: int, eval_freq: int, eval_episodes: int) -> tuple[list[float], float]:
    """One SAC + HER run; its success rates at each evaluation and its wall seconds."""
    kwargs, n_envs, normalize = recipe(name)
    blind = variant == "blind"
    env: VecEnv = make_vec_env(TASK, n_envs=n_envs, seed=seed, wrapper_class=ZeroVelocity if blind else None)
    if normalize:
        env = VecNormalize(env, gamma=kwargs["gamma"])  # as the zoo's normalize: true
    model = SAC("MultiInputPolicy", env, seed=seed, device="cpu", **kwargs)
    rates, start = [], time.perf_counter()
    for _ in range(steps // eval_freq):
        model.learn(eval_freq, reset_num_timesteps=False)
        rates.append(success_rate(model, blind, env, eval_episodes, seed))
        print(f"{name} {variant} seed {seed}: {model.num_timesteps} steps, success {rates[-1]:.2f}", flush=True)
    return rates, time.perf_counter() - start


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.reacher_velocity", description=__doc__)
    parser.add_argument("--steps", type=int, default=30_000)
    parser.add_argument("--eval-freq", type=int, default=5000)
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--recipes", nargs="+", choices=["source", "preset"], default=["source", "preset"])
    parser.add_argument("--variants", nargs="+", choices=["full", "blind"], default=["full", "blind"])
    args = parser.parse_args(argv)
    if args.eval_freq < 1 or args.steps < args.eval_freq or args.eval_episodes < 1:
        parser.error("--eval-freq and --eval-episodes must be positive and --steps at least --eval-freq")
    register_envs()
    command = "python -m benchmarks.reacher_velocity " + shlex.join(sys.argv[1:] if argv is None else argv)
    print(command)
    rows = []
    for name in args.recipes:
        for variant in args.variants:
            for seed in args.seeds:
                rates, seconds = run(name, variant, seed, args.steps, args.eval_freq, args.eval_episodes)
                cells = " | ".join(f"{rate:.2f}" for rate in rates)
                rows.append(f"| {name} | {variant} | {seed} | {cells} | {seconds:.0f} |")
    steps = range(args.eval_freq, args.eval_freq * (args.steps // args.eval_freq) + 1, args.eval_freq)
    print(f"\n{command}\n")
    print("| recipe | observation | seed | " + " | ".join(f"success at {step}" for step in steps) + " | seconds |")
    print("|---|---|---|" + "---|" * (len(steps) + 1))
    print("\n".join(rows))


if __name__ == "__main__":
    main()
