"""
Speed and learning of UDPO + HER and the package's ``LeanSAC`` + HER against SB3's ``SAC`` + HER as shipped: env
steps/s, their ratios to SB3's SAC, and eval success every ``--eval-every`` steps.

The algorithms are trained alternately, ``--chunk`` env steps each in turn (250 by default: the noise of a shared machine
changes within seconds), in the same process, so that machine noise hits them alike; ``steps_per_s`` counts training
time only (not evaluation). Tasks (``--task``):

- ``fetch-reach``: gymnasium-robotics' ``FetchReach-v4`` with RL-Zoo's settings (64x64 nets, VecNormalize, gamma
  0.95, lr 1e-3, batch 256, HER future x4, 1000 warm-up steps); UDPO with Delta 200 (50 refit steps, lr 1e-3);
- ``ant-locomotion``: ``Pilot/AntLocomotion-v0``, 256x256 nets, batch 256, 2 envs (one gradient step per 2 env
  steps), lr 1e-3, gamma 0.98, HER future x4, 400 warm-up steps; UDPO with Delta 1500.

Usage::

    python -m benchmarks.udpo_vs_sac --task fetch-reach --seeds 0 1 2 --steps 6000
    python -m benchmarks.udpo_vs_sac --task ant-locomotion --seeds 0 1 2 --steps 4000

All run with the same number of torch threads (``--threads``, 1 by default).
"""

import argparse
import copy
import time
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import gymnasium_robotics
import numpy as np
import torch as th
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize

from sb3_pilot import UDPO
from sb3_pilot.sac import LeanSAC

gym.register_envs(gymnasium_robotics)

ALGOS: dict[str, type[BaseAlgorithm]] = {"sac": SAC, "lean_sac": LeanSAC, "udpo": UDPO}
HER = dict(replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=dict(goal_selection_strategy="future", n_sampled_goal=4))


@dataclass(frozen=True)
class Task:
    """
    A benchmark task: the env, its vectorisation and every algorithm's settings.

    :param env_id: registered env ID
    :param n_envs: envs stepped per vec step (one gradient step per vec step)
    :param normalize: wrap in VecNormalize (RL-Zoo's ``normalize: true``)
    :param kwargs: settings of every algorithm
    :param udpo_kwargs: UDPO's own settings (overridable on the command line)
    """

    env_id: str
    n_envs: int
    normalize: bool
    kwargs: dict[str, Any]
    udpo_kwargs: dict[str, Any] = field(default_factory=dict)


TASKS = {
    "fetch-reach": Task(
        "FetchReach-v4",
        n_envs=1,
        normalize=True,
        kwargs=dict(
            buffer_size=1_000_000,
            batch_size=256,
            gamma=0.95,
            learning_rate=1e-3,
            learning_starts=1000,
            policy_kwargs=dict(net_arch=[64, 64]),
            **HER,
        ),
        udpo_kwargs=dict(inverse_dynamics_interval=200, inverse_dynamics_learning_rate=1e-3),
    ),
    "ant-locomotion": Task(
        "Pilot/AntLocomotion-v0",
        n_envs=2,
        normalize=False,
        kwargs=dict(
            buffer_size=1_000_000,
            batch_size=256,
            gamma=0.98,
            learning_rate=1e-3,
            learning_starts=400,
            policy_kwargs=dict(net_arch=[256, 256]),
            **HER,
        ),
        udpo_kwargs=dict(inverse_dynamics_interval=1500, inverse_dynamics_learning_rate=1e-3),
    ),
}


def make_model(algo: str, task: Task, seed: int, udpo_kwargs: dict[str, Any]) -> BaseAlgorithm:
    env = make_vec_env(task.env_id, n_envs=task.n_envs, seed=seed)
    if task.normalize:
        env = VecNormalize(env, gamma=task.kwargs["gamma"])
    kwargs = copy.deepcopy(task.kwargs)  # SB3 writes into policy_kwargs
    if algo == "udpo":
        kwargs.update(task.udpo_kwargs, **udpo_kwargs)
    return ALGOS[algo]("MultiInputPolicy", env, seed=seed, **kwargs)


def eval_success(model: BaseAlgorithm, env_id: str, n_episodes: int, seed: int) -> float:
    """Deterministic success rate on fresh episodes, with the training normalisation (if any) frozen."""
    eval_env = make_vec_env(env_id, n_envs=1, seed=seed + 10_000)
    train_env = model.get_vec_normalize_env()
    if train_env is not None:
        eval_env = VecNormalize(eval_env, training=False, norm_reward=False)
        eval_env.obs_rms = train_env.obs_rms
    successes = []
    obs = eval_env.reset()
    while len(successes) < n_episodes:
        action, _ = model.predict(obs, deterministic=True)
        obs, _, dones, infos = eval_env.step(action)
        if dones[0]:
            successes.append(infos[0].get("is_success", infos[0].get("success", 0.0)))
    return float(np.mean(successes))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", choices=tuple(TASKS), default="fetch-reach")
    parser.add_argument("--algos", nargs="+", choices=tuple(ALGOS), default=list(ALGOS))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--chunk", type=int, default=250, help="env steps each algorithm trains in turn")
    parser.add_argument("--eval-every", type=int, default=2000)
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--threads", type=int, default=1, help="torch threads (1: robust to a busy 2-core machine)")
    parser.add_argument("--planner-coef", type=float, default=None, help="UDPO's lambda (default: UDPO's)")
    args = parser.parse_args()
    if "sac" not in args.algos:
        parser.error("--algos must include sac: the ratios are to SB3's SAC")
    th.set_num_threads(args.threads)
    task = TASKS[args.task]
    udpo_kwargs: dict[str, Any] = {}
    if args.planner_coef is not None:
        udpo_kwargs["planner_coef"] = args.planner_coef
    print(f"task={args.task} env={task.env_id} steps={args.steps} algos={args.algos} udpo_kwargs={udpo_kwargs}")
    ratios: dict[str, list[float]] = {algo: [] for algo in args.algos}
    for seed in args.seeds:
        models = {algo: make_model(algo, task, seed, udpo_kwargs) for algo in args.algos}
        train_seconds = dict.fromkeys(models, 0.0)
        next_eval = args.eval_every
        while models["sac"].num_timesteps < args.steps:
            for algo, model in models.items():
                start = time.perf_counter()
                model.learn(args.chunk, reset_num_timesteps=False)
                train_seconds[algo] += time.perf_counter() - start
            if models["sac"].num_timesteps < next_eval:
                continue
            next_eval += args.eval_every
            for algo, model in models.items():
                success = eval_success(model, task.env_id, args.eval_episodes, seed)
                print(
                    f"seed={seed} algo={algo} steps={model.num_timesteps} eval_success={success:.2f} "
                    f"steps_per_s={model.num_timesteps / train_seconds[algo]:.1f}",
                    flush=True,
                )
        fps = {algo: models[algo].num_timesteps / train_seconds[algo] for algo in models}
        for algo in models:
            ratios[algo].append(fps[algo] / fps["sac"])
        print(f"seed={seed} " + ", ".join(f"{algo} {fps[algo]:.1f} steps/s ({ratios[algo][-1]:.2f}x SAC)" for algo in fps))
    for algo, values in ratios.items():
        print(f"{algo}: steps/s ratio to SB3 SAC over seeds {args.seeds}: mean {np.mean(values):.2f} ({values})")


if __name__ == "__main__":
    main()
