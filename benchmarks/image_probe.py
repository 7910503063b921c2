"""
Does a pixel agent's encoder see where the arm is? A linear probe of the image features of a model trained on an image
task (e.g. a run of ``benchmarks.image_recipe``): frames of random-action episodes of its training task (rebuilt from
the run's saved settings), the image features of the policy's encoder (in evaluation mode: no augmentation), and a
ridge regression from them to ``achieved_goal`` (the fingertip's or the gripper's position), fitted on the first two
thirds of the episodes and scored on the rest (R^2, averaged over the coordinates, and the median distance between
predicted and true position, to set beside the task's success radius). Beside it, the same probe of an
untrained encoder (the model's, re-initialised). Trained features that predict the position no better than untrained
ones say the encoder has not learned to see it: what limits the agent is its representation, not its critic or actor.
And whether the policy reads its goal: the spread (standard deviation) of its deterministic actions on 100 of those
frames each shown 8 goals drawn from the goal disk's area, against their spread over the frames; a policy whose actions
do not move with the goal does not act towards it.

Usage::

    python -m benchmarks.image_probe MODEL [MODEL ...] [--episodes 60] [--seed 0]

Prints the command and one markdown row per model.
"""

from __future__ import annotations

import argparse
import copy
import shlex
import sys
from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.policies import BasePolicy
from stable_baselines3.common.vec_env import VecNormalize
from torch import nn

from sb3_pilot.experiments.challenges.controller import training_task
from sb3_pilot.experiments.challenges.stages import load_zoo_model

#: Ridge penalty on the standardised features.
RIDGE = 1.0
#: Frames per forward pass.
CHUNK = 500


def random_frames(model_path: Path, episodes: int, seed: int) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """
    Observations of ``episodes`` random-action episodes of the model's training task.

    :return: the observations (stacked per key), their ``achieved_goal`` and each one's episode index
    """
    env = training_task(model_path)
    env.action_space.seed(seed)
    observations: list[dict[str, np.ndarray]] = []
    episode_of: list[int] = []
    for episode in range(episodes):
        observation, _ = env.reset(seed=10_000 * seed + episode)
        done = False
        while not done:
            observations.append(observation)
            episode_of.append(episode)
            observation, _, terminated, truncated, _ = env.step(env.action_space.sample())
            done = terminated or truncated
    env.close()
    stacked = {key: np.stack([observation[key] for observation in observations]) for key in observations[0]}
    return stacked, stacked["achieved_goal"].astype(np.float64), np.array(episode_of)


def image_features(policy: BasePolicy, extractor: nn.Module, observations: dict[str, np.ndarray]) -> np.ndarray:
    """The extractor's image features of the observations (its output without the ``desired_goal`` it appends)."""
    goal_dim = observations["desired_goal"].shape[-1]
    n = len(observations["desired_goal"])
    features = []
    with th.no_grad():
        for start in range(0, n, CHUNK):
            chunk = {key: value[start : start + CHUNK] for key, value in observations.items()}
            tensor, _ = policy.obs_to_tensor(chunk)
            features.append(policy.extract_features(tensor, extractor)[:, :-goal_dim].numpy())
    return np.concatenate(features)


def probe_r2(features: np.ndarray, targets: np.ndarray, train: np.ndarray) -> tuple[float, float]:
    """
    R^2 on the held-out rows of a ridge regression fitted on the ``train`` rows (mean over target coordinates), and the
    median Euclidean error of its held-out predictions (in the goal's units, to set beside the success radius).
    """
    mean, std = features[train].mean(axis=0), features[train].std(axis=0) + 1e-8
    x = np.hstack([(features - mean) / std, np.ones((len(features), 1))])
    penalty = RIDGE * np.eye(x.shape[1])
    penalty[-1, -1] = 0.0  # no penalty on the intercept
    weights = np.linalg.solve(x[train].T @ x[train] + penalty, x[train].T @ targets[train])
    test = ~train
    error = targets[test] - x[test] @ weights
    total = ((targets[test] - targets[test].mean(axis=0)) ** 2).sum(axis=0)
    return float(np.mean(1.0 - (error**2).sum(axis=0) / total)), float(np.median(np.linalg.norm(error, axis=-1)))


def goal_spread(
    model: BaseAlgorithm, vec_normalize: VecNormalize | None, observations: dict[str, np.ndarray], seed: int
) -> tuple[float, float]:
    """
    The policy's deterministic actions on 100 frames, each with 8 goals drawn uniformly over the disk of the frames'
    own goals' largest radius: their spread across the goals of a frame and across the frames of a goal draw.
    """
    rng = np.random.default_rng(seed)
    frames = rng.choice(len(observations["desired_goal"]), size=min(100, len(observations["desired_goal"])), replace=False)
    radius = np.linalg.norm(observations["desired_goal"], axis=-1).max()
    actions = []
    for _ in range(8):
        shown = {key: value[frames].copy() for key, value in observations.items()}
        distance, angle = radius * np.sqrt(rng.random(len(frames))), rng.random(len(frames)) * 2 * np.pi
        goals = np.stack([distance * np.cos(angle), distance * np.sin(angle)], axis=1)
        shown["desired_goal"] = goals.astype(shown["desired_goal"].dtype)
        seen = vec_normalize.normalize_obs(shown) if vec_normalize is not None else shown
        actions.append(model.predict(seen, deterministic=True)[0])
    stacked = np.stack(actions)  # goals x frames x action
    return float(stacked.std(axis=0).mean()), float(stacked.std(axis=1).mean())


def probe(model_path: Path, episodes: int, seed: int) -> tuple[tuple[float, float], tuple[float, float], int, float, float]:
    """
    R^2 and median error (:func:`probe_r2`) of the trained and of a re-initialised encoder's features, the number of
    frames, and the actions' spread across goals and across frames (:func:`goal_spread`).
    """
    model, vec_normalize = load_zoo_model(model_path)
    policy = model.policy
    policy.set_training_mode(False)
    observations, positions, episode_of = random_frames(model_path, episodes, seed)
    train = episode_of < (2 * episodes) // 3
    trained = policy.actor.features_extractor
    untrained = copy.deepcopy(trained)
    th.manual_seed(seed)
    for module in untrained.modules():
        if hasattr(module, "reset_parameters"):
            module.reset_parameters()
    trained_r2, untrained_r2 = (
        probe_r2(image_features(policy, extractor, observations), positions, train) for extractor in (trained, untrained)
    )
    return (trained_r2, untrained_r2, len(positions), *goal_spread(model, vec_normalize, observations, seed))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.image_probe", description=__doc__)
    parser.add_argument("models", type=Path, nargs="+", help="zoo models trained on an image task")
    parser.add_argument("--episodes", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    missing = [str(path) for path in args.models if not path.is_file()]
    if missing:
        parser.error(f"no model at {', '.join(missing)}")
    if args.episodes < 3:
        parser.error("--episodes must be at least 3 (two thirds fit the probe, the rest score it)")
    print("python -m benchmarks.image_probe " + shlex.join(sys.argv[1:] if argv is None else argv))
    print(
        "| model | frames | R^2 of achieved_goal, trained encoder | its median error | R^2, the same encoder untrained "
        "| its median error | action spread across goals | across frames |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for path in args.models:
        (trained, trained_error), (untrained, untrained_error), frames, across_goals, across_frames = probe(
            path, args.episodes, args.seed
        )
        print(
            f"| {path} | {frames} | {trained:.2f} | {trained_error:.3f} | {untrained:.2f} | {untrained_error:.3f} "
            f"| {across_goals:.3f} | {across_frames:.3f} |"
        )


if __name__ == "__main__":
    main()
