"""
How finely can the pixel encoder locate the arm, when taught directly? The image preset's encoder (``PixelGoalExtractor``'s
convolutions, then a 256-256 ReLU head) trained by regression alone from the frames of random-action episodes of an
image task to their ``achieved_goal``, with and without DrQ's random shift, scored on held-out episodes by the median
distance between predicted and true position, to set beside the task's success radius and beside what an agent's
features give (``benchmarks.image_probe``). An upper bound on what the critic's loss can teach the same encoder.

Usage::

    OMP_NUM_THREADS=1 MUJOCO_GL=osmesa python -m benchmarks.image_localisation [--task Pilot/ReacherImage-v0]
        [--steps 3000] [--shifts 0 4] [--episodes 120] [--seed 0]

Prints the command and one markdown row per shift.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time

import gymnasium as gym
import numpy as np
import torch as th
from torch import nn

from sb3_pilot.common import PixelGoalExtractor
from sb3_pilot.envs import register_envs

#: The image entry of the tasks' Dict observations.
IMAGE_KEY = "observation"

#: Minibatch size (the image preset's).
BATCH_SIZE = 64
#: Adam's learning rate (the image preset's).
LEARNING_RATE = 3e-4


def random_frames(task: str, episodes: int, seed: int, **env_kwargs: object) -> tuple[th.Tensor, th.Tensor, np.ndarray]:
    """Frames (channel-first uint8), their ``achieved_goal`` and episode index, of random-action episodes."""
    register_envs()
    env = gym.make(task, **env_kwargs)
    env.action_space.seed(seed)
    frames, goals, episode_of = [], [], []
    for episode in range(episodes):
        observation, _ = env.reset(seed=10_000 * seed + episode)
        done = False
        while not done:
            frames.append(observation[IMAGE_KEY])
            goals.append(observation["achieved_goal"])
            episode_of.append(episode)
            observation, _, terminated, truncated, _ = env.step(env.action_space.sample())
            done = terminated or truncated
    env.close()
    images = th.as_tensor(np.stack(frames)).permute(0, 3, 1, 2).contiguous()
    return images, th.as_tensor(np.stack(goals), dtype=th.float32), np.array(episode_of)


def localisation_error(
    images: th.Tensor, goals: th.Tensor, train: np.ndarray, shift: int, steps: int, seed: int
) -> tuple[float, float]:
    """
    Train the preset's encoder and a 256-256 head by regression to the goals on the ``train`` rows.

    :return: the held-out median distance between predicted and true goal, and the share of held-out frames within 0.02
    """
    th.manual_seed(seed)
    space = gym.spaces.Dict(
        {
            IMAGE_KEY: gym.spaces.Box(0, 255, shape=tuple(images.shape[1:]), dtype=np.uint8),
            "desired_goal": gym.spaces.Box(-np.inf, np.inf, shape=(goals.shape[1],)),
        }
    )
    extractor = PixelGoalExtractor(space, encoder="nature", random_shift=shift)
    model = nn.Sequential(extractor.cnn, extractor.head, nn.Linear(extractor.features_dim - goals.shape[1], 256), nn.ReLU())
    model.append(nn.Linear(256, goals.shape[1]))
    augmentation = extractor.augmentation  # DrQ's shift (None without one), applied to the training batches only
    optimizer = th.optim.Adam(model.parameters(), lr=LEARNING_RATE)
    train_rows = th.as_tensor(np.flatnonzero(train))
    for _ in range(steps):
        rows = train_rows[th.randint(len(train_rows), (BATCH_SIZE,))]
        batch = images[rows].float() / 255.0
        if augmentation is not None:
            batch = augmentation(batch)
        loss = ((model(batch) - goals[rows]) ** 2).sum(dim=1).mean()
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
    test = th.as_tensor(np.flatnonzero(~train))
    with th.no_grad():
        error = (model(images[test].float() / 255.0) - goals[test]).norm(dim=1)
    return float(error.median()), float((error < 0.02).float().mean())


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.image_localisation", description=__doc__)
    parser.add_argument("--task", default="Pilot/ReacherImage-v0")
    parser.add_argument("--steps", type=int, default=3000, help="gradient steps of the regression")
    parser.add_argument("--shifts", type=int, nargs="+", default=[0, 4], help="DrQ's largest random shift, in pixels")
    parser.add_argument("--episodes", type=int, default=120, help="random-action episodes (the last quarter held out)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.steps < 1 or args.episodes < 4 or min(args.shifts) < 0:
        parser.error("--steps must be positive, --episodes at least 4 and --shifts non-negative")
    print("python -m benchmarks.image_localisation " + shlex.join(sys.argv[1:] if argv is None else argv))
    images, goals, episode_of = random_frames(args.task, args.episodes, args.seed, show_target=False)
    train = episode_of < (3 * args.episodes) // 4
    print(f"{len(images)} frames of {args.task} (target hidden), {train.sum()} to train, goal std {goals.std(0).tolist()}")
    print("| random shift (px) | steps | held-out median error | share within 0.02 | seconds |")
    print("|---|---|---|---|---|")
    for shift in args.shifts:
        start = time.perf_counter()
        median, within = localisation_error(images, goals, train, shift, args.steps, args.seed)
        print(f"| {shift} | {args.steps} | {median:.4f} | {within:.2f} | {time.perf_counter() - start:.0f} |", flush=True)


if __name__ == "__main__":
    main()
