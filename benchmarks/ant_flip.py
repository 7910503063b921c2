"""
How often does each Ant end up on its back? ``Pilot/AntLocomotion-v0`` (gymnasium's Ant) against ``-v1`` (the
hierarchical-RL literature's, :data:`~sb3_pilot.envs.locomotion.ANT_XML_FILES`), first under random actions, then
under a SAC + HER controller trained on the sparse task.

- ``random``: ``--episodes`` episodes of 500 steps (Ant-Maze's length) per Ant, under uniform random actions and under
  bang-bang ones (each motor at either end of its range): the share of steps on its back (``ant_up_z < 0``) and tilted
  more than 60 degrees (``ant_up_z < 0.5``), and the median xy drift after 500 steps. Seconds.
- ``trained``: SAC + HER with ``hyperparams/cpu/sac.yml``'s ``Pilot/AntLocomotion-v0`` entry (4 envs, batch 256,
  HER ``future`` 4, 256x256 networks), the same settings for both Ants, ``--steps`` env steps per seed; the shares
  above over all its training steps and over ``--eval-episodes`` deterministic episodes of the task (100 steps) after
  training, with the success rate and median final distance. About 15-25 minutes a run on one core at 100k steps;
  each finished run is written to ``<root>/trained_<version>_seed<k>.json`` and skipped when run again.

Usage::

    python -m benchmarks.ant_flip random --episodes 20 --root zoo_runs/ant-flip
    python -m benchmarks.ant_flip trained --seeds 0 1 --steps 100000 --root zoo_runs/ant-flip

Each writes its JSON under ``--root`` and prints a markdown table with the command.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import yaml

from sb3_pilot.envs import ant_up_z, register_envs

VERSIONS = ("v0", "v1")
#: ``ant_up_z`` below which the Ant counts as on its back, and as tilted more than 60 degrees
ON_BACK, TILTED = 0.0, 0.5
RANDOM_EPISODE_STEPS = 500


def ant_task(version: str) -> str:
    """:return: the ID of the open-ground Ant task of this version"""
    if version not in VERSIONS:
        raise ValueError(f"version must be one of {VERSIONS}, got {version!r}")
    return f"Pilot/AntLocomotion-{version}"


def random_actions(env: gym.Env, kind: str, rng: np.random.Generator) -> np.ndarray:
    """:return: a uniform (``kind="uniform"``) or bang-bang (``"bang-bang"``) action of ``env``'s action space"""
    low, high = env.action_space.low, env.action_space.high
    if kind == "uniform":
        return rng.uniform(low, high)
    return np.where(rng.random(low.shape) < 0.5, low, high)


def random_flips(version: str, kind: str, episodes: int, seed: int = 0) -> dict[str, float]:
    """
    :param version: ``"v0"`` or ``"v1"``
    :param kind: ``"uniform"`` or ``"bang-bang"``
    :param episodes: episodes of :data:`RANDOM_EPISODE_STEPS` steps
    :param seed: seed of the resets and of the actions
    :return: shares of steps on its back and tilted, and the median drift after the episode
    """
    env = gym.make(ant_task(version), max_episode_steps=RANDOM_EPISODE_STEPS)
    rng = np.random.default_rng(seed)
    up_z, drift = [], []
    for episode in range(episodes):
        env.reset(seed=seed * 10_000 + episode)
        ant = env.unwrapped
        for _ in range(RANDOM_EPISODE_STEPS):
            env.step(random_actions(env, kind, rng))
            up_z.append(ant_up_z(ant.data.qpos))
        drift.append(float(np.linalg.norm(ant.data.qpos[:2])))
    up = np.array(up_z)
    return {"on_back": float(np.mean(up < ON_BACK)), "tilted": float(np.mean(up < TILTED)), "drift": float(np.median(drift))}


def sac_her_settings(steps: int) -> dict[str, Any]:
    """SAC's keyword arguments from ``hyperparams/cpu/sac.yml``'s ``Pilot/AntLocomotion-v0`` entry (and ``n_envs``)."""
    from stable_baselines3 import HerReplayBuffer

    from sb3_pilot.experiments.zoo import hyperparams_dir

    entry = yaml.safe_load((hyperparams_dir() / "cpu" / "sac.yml").read_text())["Pilot/AntLocomotion-v0"]
    return {
        "n_envs": int(entry["n_envs"]),
        "gamma": float(entry["gamma"]),
        "batch_size": int(entry["batch_size"]),
        "learning_rate": float(entry["learning_rate"]),
        "learning_starts": int(entry["learning_starts"]),
        "buffer_size": min(int(entry["buffer_size"]), steps),
        "replay_buffer_class": HerReplayBuffer,
        "replay_buffer_kwargs": eval(entry["replay_buffer_kwargs"]),  # the zoo's own reading of this string
    }


def trained_flips(version: str, seed: int, steps: int, eval_episodes: int) -> dict[str, Any]:
    """
    Train SAC + HER on the version's task and measure its flips during training and after.

    :return: the shares on its back and tilted over training and over the evaluation, success rate, median final
        distance, env steps per second
    """
    from stable_baselines3 import SAC
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env

    settings = sac_her_settings(steps)
    venv = make_vec_env(ant_task(version), n_envs=settings.pop("n_envs"), seed=seed)
    ants = [env.unwrapped for env in venv.envs]

    class UpZ(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.up_z: list[float] = []

        def _on_step(self) -> bool:
            self.up_z.extend(ant_up_z(ant.data.qpos) for ant in ants)
            return True

    model = SAC("MultiInputPolicy", venv, seed=seed, device="cpu", **settings)
    callback = UpZ()
    start = time.time()
    model.learn(steps, callback=callback)
    seconds = time.time() - start
    env = gym.make(ant_task(version))
    ant = env.unwrapped
    eval_up_z, successes, distances = [], [], []
    for episode in range(eval_episodes):
        obs, _ = env.reset(seed=1_000_000 + episode)
        done, info = False, {}
        while not done:
            obs, _, terminated, truncated, info = env.step(model.predict(obs, deterministic=True)[0])
            eval_up_z.append(ant_up_z(ant.data.qpos))
            done = terminated or truncated
        successes.append(float(info["is_success"]))
        distances.append(float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"])))
    train_up, eval_up = np.array(callback.up_z), np.array(eval_up_z)
    return {
        "version": version,
        "seed": seed,
        "steps": steps,
        "train_on_back": float(np.mean(train_up < ON_BACK)),
        "train_tilted": float(np.mean(train_up < TILTED)),
        "eval_on_back": float(np.mean(eval_up < ON_BACK)),
        "eval_tilted": float(np.mean(eval_up < TILTED)),
        "eval_episodes": eval_episodes,
        "success": float(np.mean(successes)),
        "median_final_distance": float(np.median(distances)),
        "env_steps_per_s": steps / seconds,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("part", choices=("random", "trained"))
    parser.add_argument("--root", type=Path, required=True, help="folder of the JSON results")
    parser.add_argument("--episodes", type=int, default=20, help="random: episodes per Ant and action kind")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="trained: training seeds")
    parser.add_argument("--steps", type=int, default=100_000, help="trained: env steps per run")
    parser.add_argument("--eval-episodes", type=int, default=30, help="trained: evaluation episodes")
    parser.add_argument("--versions", nargs="+", choices=VERSIONS, default=list(VERSIONS))
    args = parser.parse_args(argv)
    for name in ("episodes", "steps", "eval_episodes"):
        if getattr(args, name) <= 0:
            parser.error(f"--{name.replace('_', '-')} must be positive")
    register_envs()
    args.root.mkdir(parents=True, exist_ok=True)
    command = f"python -m benchmarks.ant_flip {shlex.join(argv if argv is not None else sys.argv[1:])}"
    print(f"`{command}`\n")
    if args.part == "random":
        rows = [
            {"version": version, "actions": kind, **random_flips(version, kind, args.episodes)}
            for version in args.versions
            for kind in ("uniform", "bang-bang")
        ]
        (args.root / "random.json").write_text(json.dumps({"command": command, "rows": rows}, indent=2))
        print("| Ant | actions | on its back | tilted > 60 deg | median drift after 500 steps |\n|---|---|---|---|---|")
        for row in rows:
            print(f"| {row['version']} | {row['actions']} | {row['on_back']:.3f} | {row['tilted']:.3f} | {row['drift']:.2f} |")
        return
    for version in args.versions:
        for seed in args.seeds:
            path = args.root / f"trained_{version}_seed{seed}.json"
            if path.is_file():
                continue
            result = trained_flips(version, seed, args.steps, args.eval_episodes)
            path.write_text(json.dumps({"command": command, **result}, indent=2))
            print(f"{path}: {result}", flush=True)
    print(
        "| Ant | seed | steps | on its back (training) | tilted (training) | on its back (eval) | tilted (eval) |"
        " success | median final distance |\n|---|---|---|---|---|---|---|---|---|"
    )
    for path in sorted(args.root.glob("trained_*.json")):
        r = json.loads(path.read_text())
        print(
            f"| {r['version']} | {r['seed']} | {r['steps']} | {r['train_on_back']:.3f} | {r['train_tilted']:.3f} |"
            f" {r['eval_on_back']:.3f} | {r['eval_tilted']:.3f} | {r['success']:.2f} | {r['median_final_distance']:.2f} |"
        )


if __name__ == "__main__":
    main()
