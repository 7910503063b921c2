"""
Pixel env steps per second of the image preset on CPU, today's path against the fast ones, in one run: ``LeanSAC`` +
``PixelGoalSACPolicy`` (NatureCNN, random shift 4, batch 64, HER, one gradient step per 2 env steps:
``hyperparams/image/sac.yml``'s ``Pilot/FetchReachImage-v0`` entry) training on ``Pilot/FetchReachImage-v0``.

- ``old``: today's preset: the task's frames as ``Pilot/FetchReachImage-v0`` draws them (4x multisampling), and the
  per-parameter Adam the pixel policy had before issue 61 (``optimizer_kwargs=dict(foreach=False)``);
- ``new``: the fast path, same computation: frames drawn without multisampling (``env_kwargs: {antialias: false}``)
  and the policy's fused Adam (the same updates up to float rounding);
- ``drqv2``: ``new`` with DrQ-v2's target (``policy_kwargs: {online_target_features: true}``): the target critic reads
  the shared encoder's features of the next observations, so the TD targets change (the curve check says by how much).

All encode a gradient step's observations once (``PixelGoalSACPolicy.encode``). ``old`` and ``new`` encode the next
observations twice, for the actor and through the target critic's encoder copy (3 encoder passes a gradient step),
``drqv2`` once, shared (2 passes; counted below).

The paths alternate, ``--rounds`` times each, each round a fresh model (same seed) that first fills ``learning_starts``
and then trains ``--steps`` env steps, timed by the wall clock and by the process's CPU time (less sensitive to
other processes on a loaded machine). ``--frames DIR`` saves a frame of the old and the new path as PNG, with their
mean absolute pixel difference over ``--frame-count`` frames; ``--curve N`` trains each of ``--curve-paths`` ``N``
steps from the same seed and evaluates success and final distance over 20 episodes (the cheap check that the curve
is unchanged; ``--rounds 0``: the check alone).

Usage::

    OMP_NUM_THREADS=1 MUJOCO_GL=osmesa nice -n 10 python -m benchmarks.pixel_speed [--steps 400] [--rounds 2] \\
        [--paths old,new,drqv2] [--frames docs/results/pixel_frames] [--curve 3000] [--curve-paths old,new,drqv2]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
import yaml
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.env_util import make_vec_env

from sb3_pilot.envs import register_envs
from sb3_pilot.experiments.zoo import hyperparams_dir
from sb3_pilot.pixels import PixelGoalSACPolicy
from sb3_pilot.sac import LeanSAC

ENV_ID = "Pilot/FetchReachImage-v0"
#: env kwargs of each path
PATHS: dict[str, dict[str, Any]] = {"old": {"antialias": True}, "new": {"antialias": False}, "drqv2": {"antialias": False}}
#: policy kwargs each path adds to the preset's: today's per-parameter Adam, the fused default, DrQ-v2's target
POLICY_KWARGS: dict[str, dict[str, Any]] = {
    "old": {"optimizer_kwargs": {"foreach": False}},
    "new": {},
    "drqv2": {"online_target_features": True},
}
#: the preset's settings that the benchmark takes from its YAML entry (the replay buffer is sized to the run)
PRESET_KEYS = ("gamma", "batch_size", "train_freq", "gradient_steps", "learning_rate", "policy_kwargs")
#: SB3's SAC default, which the entry keeps
LEARNING_STARTS = 100


def preset() -> dict[str, Any]:
    """``hyperparams/image/sac.yml``'s ``Pilot/FetchReachImage-v0`` entry as ``LeanSAC`` arguments (as the zoo reads it)."""
    entry = yaml.safe_load((hyperparams_dir() / "image" / "sac.yml").read_text())[ENV_ID]
    settings = {key: entry[key] for key in PRESET_KEYS}
    settings["policy_kwargs"] = eval(settings["policy_kwargs"])  # a string in the YAML, as the zoo evaluates it
    assert entry["replay_buffer_class"] == "HerReplayBuffer" and entry["n_envs"] == 1, entry
    replay_buffer_kwargs = eval(entry["replay_buffer_kwargs"])
    return dict(settings, replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=replay_buffer_kwargs)


def make_model(path: str, buffer_size: int, seed: int = 0) -> LeanSAC:
    """The preset's model on the path's frames, with the path's policy settings (``PATHS``, ``POLICY_KWARGS``)."""
    env = make_vec_env(ENV_ID, seed=seed, env_kwargs=PATHS[path])
    settings = dict(preset(), learning_starts=LEARNING_STARTS, buffer_size=buffer_size, seed=seed, device="cpu")
    settings["policy_kwargs"] = dict(settings["policy_kwargs"], **POLICY_KWARGS[path])
    return LeanSAC(PixelGoalSACPolicy, env, **settings)


def encoder_passes(model: LeanSAC, gradient_steps: int = 4) -> float:
    """Batch passes through the encoders (the shared one and the target's copy) per gradient step."""
    first_convs = [
        module.cnn[0] for module in (model.policy.critic.features_extractor, model.critic_target.features_extractor)
    ]
    calls: list[int] = []
    handles = [conv.register_forward_hook(lambda *args: calls.append(1)) for conv in first_convs]
    model.train(gradient_steps, model.batch_size)
    for handle in handles:
        handle.remove()
    return len(calls) / gradient_steps


def time_path(path: str, steps: int) -> dict[str, float]:
    """Env steps per second (wall, CPU) of ``steps`` training steps after ``learning_starts``, and frame times."""
    model = make_model(path, buffer_size=steps + 2 * LEARNING_STARTS)
    model.learn(LEARNING_STARTS + 2)
    passes = encoder_passes(model)
    wall, cpu = time.perf_counter(), time.process_time()
    model.learn(steps, reset_num_timesteps=False)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    task = model.env.envs[0].unwrapped
    frame_cpu = time.process_time()
    for _ in range(50):
        task._render_image()
    frame_ms = (time.process_time() - frame_cpu) / 50 * 1e3
    model.env.close()
    return {"wall": steps / wall, "cpu": steps / cpu, "frame_ms": frame_ms, "passes": passes}


def compare_frames(folder: Path, count: int) -> float:
    """Save one frame of each path as PNG; the mean absolute pixel difference (0-255) over ``count`` frames."""
    from PIL import Image

    frames: dict[str, list[np.ndarray]] = {}
    for path in ("old", "new"):
        kwargs = PATHS[path]
        env = gym.make(ENV_ID, **kwargs)
        obs, _ = env.reset(seed=0)
        rng = np.random.default_rng(0)
        frames[path] = [obs["observation"]]
        for _ in range(count - 1):
            obs, *_ = env.step(rng.uniform(-1, 1, 4).astype(np.float32))
            frames[path].append(obs["observation"])
        env.close()
    folder.mkdir(parents=True, exist_ok=True)
    for path, images in frames.items():
        Image.fromarray(images[10]).resize((256, 256), Image.NEAREST).save(folder / f"fetch_reach_image_{path}.png")
    old, new = (np.asarray(frames[path], dtype=np.int16) for path in frames)
    return float(np.abs(old - new).mean())


def curve(path: str, steps: int, episodes: int = 20) -> tuple[float, float]:
    """Success rate and mean final distance over ``episodes`` deterministic episodes after ``steps`` of training."""
    model = make_model(path, buffer_size=steps)
    model.learn(steps)
    env = gym.make(ENV_ID, **PATHS[path])
    successes, distances = [], []
    for episode in range(episodes):
        obs, _ = env.reset(seed=10_000 + episode)
        done, info = False, {}
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        successes.append(float(info["is_success"]))
        distances.append(float(np.linalg.norm(obs["achieved_goal"] - obs["desired_goal"])))
    env.close()
    return float(np.mean(successes)), float(np.mean(distances))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=400, help="timed env steps per round and path (after warm-up)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds per path, alternated")
    parser.add_argument("--frames", type=Path, default=None, help="folder for a PNG frame of each path")
    parser.add_argument("--frame-count", type=int, default=100, help="frames compared for the pixel difference")
    parser.add_argument("--curve", type=int, default=0, help="env steps of the curve check per path (0: none)")
    parser.add_argument("--paths", default="old,new,drqv2", help="the timed paths, comma-separated (old first)")
    parser.add_argument("--curve-paths", default="old,new,drqv2", help="the paths of the curve check, comma-separated")
    args = parser.parse_args()
    th.set_num_threads(1)
    register_envs()
    print(f"command: python -m benchmarks.pixel_speed {' '.join(sys.argv[1:])}", flush=True)
    if args.frames is not None:
        difference = compare_frames(args.frames, args.frame_count)
        print(f"frames: {args.frames}/fetch_reach_image_{{old,new}}.png; mean |old - new| {difference:.2f} / 255", flush=True)
    if args.rounds:
        time_paths(args.paths.split(","), args.steps, args.rounds)
    for path in args.curve_paths.split(",") if args.curve else ():
        success, distance = curve(path, args.curve)
        print(f"curve {path}, {args.curve} steps, seed 0: success {success:.2f}, final distance {distance:.3f}", flush=True)


def time_paths(paths: list[str], steps: int, rounds: int) -> None:
    """Time the paths in turn, ``rounds`` times each, and print the medians and their ratios to the first path's."""
    results: dict[str, list[dict[str, float]]] = {path: [] for path in paths}
    for round_index in range(rounds):
        for path in paths:
            result = time_path(path, steps)
            results[path].append(result)
            print(
                f"round {round_index + 1} {path}: {result['wall']:.2f} env steps/s (wall), {result['cpu']:.2f} per CPU "
                f"second; frame {result['frame_ms']:.1f} ms CPU; {result['passes']:.0f} encoder passes a gradient step",
                flush=True,
            )
    medians = {path: {key: statistics.median(r[key] for r in rows) for key in rows[0]} for path, rows in results.items()}
    first = medians[paths[0]]
    print("| path | env steps/s (wall) | env steps per CPU second | frame (ms CPU) | encoder passes a gradient step |")
    print("|---|---|---|---|---|")
    for path, row in medians.items():
        print(f"| {path} | {row['wall']:.2f} | {row['cpu']:.2f} | {row['frame_ms']:.1f} | {row['passes']:.0f} |")
    for path in paths[1:]:
        row = medians[path]
        ratios = f"{row['wall'] / first['wall']:.2f}x | {row['cpu'] / first['cpu']:.2f}x"
        print(f"| {path} / {paths[0]} | {ratios} | | |", flush=True)


if __name__ == "__main__":
    main()
