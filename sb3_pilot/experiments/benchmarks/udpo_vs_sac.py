"""
UDPO + HER vs SB3's SAC + HER on FetchReach-v4: env steps/s, their ratio, and eval success every ``--eval-every`` steps.

Both algorithms use RL-Zoo's FetchReach settings (64x64 nets, VecNormalize, gamma 0.95, lr 1e-3, batch 256,
HER future with 4 sampled goals, 1000 warm-up steps) and are trained alternately, chunk by chunk, in the same
process, so that machine noise hits both alike. Usage::

    python -m sb3_pilot.experiments.benchmarks.udpo_vs_sac --seeds 0 1 2 --steps 6000

Both run with the same number of torch threads (``--threads``, 1 by default).
"""

import argparse
import copy
import time
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

gym.register_envs(gymnasium_robotics)

ZOO_FETCH_REACH = dict(
    buffer_size=1_000_000,
    batch_size=256,
    gamma=0.95,
    learning_rate=1e-3,
    learning_starts=1000,
    replay_buffer_class=HerReplayBuffer,
    replay_buffer_kwargs=dict(goal_selection_strategy="future", n_sampled_goal=4),
    policy_kwargs=dict(net_arch=[64, 64]),
)


def make_model(algo: str, env_id: str, seed: int, udpo_kwargs: dict[str, Any]) -> BaseAlgorithm:
    env = VecNormalize(make_vec_env(env_id, n_envs=1, seed=seed), gamma=0.95)
    kwargs = copy.deepcopy(ZOO_FETCH_REACH)  # SB3 writes into policy_kwargs
    if algo == "udpo":
        return UDPO("MultiInputPolicy", env, seed=seed, **kwargs, **udpo_kwargs)
    return SAC("MultiInputPolicy", env, seed=seed, **kwargs)


def eval_success(model: BaseAlgorithm, env_id: str, n_episodes: int, seed: int) -> float:
    """Deterministic success rate on fresh episodes, with the training normalisation frozen."""
    train_env = model.get_vec_normalize_env()
    eval_env = VecNormalize(make_vec_env(env_id, n_envs=1, seed=seed + 10_000), training=False, norm_reward=False)
    eval_env.obs_rms = train_env.obs_rms
    successes = []
    obs = eval_env.reset()
    while len(successes) < n_episodes:
        action, _ = model.predict(obs, deterministic=True)
        obs, _, dones, infos = eval_env.step(action)
        if dones[0]:
            successes.append(infos[0]["is_success"])
    return float(np.mean(successes))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="FetchReach-v4")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--eval-every", type=int, default=2000)
    parser.add_argument("--eval-episodes", type=int, default=20)
    parser.add_argument("--threads", type=int, default=1, help="torch threads (1: robust to a busy 2-core machine)")
    parser.add_argument("--planner-coef", type=float, default=1e-2)
    parser.add_argument("--plan-target", default="buffer", choices=("buffer", "policy"), help="UDPO's plan_target")
    parser.add_argument("--inverse-dynamics-interval", type=int, default=200)
    parser.add_argument("--inverse-dynamics-gradient-steps", type=int, default=50)
    parser.add_argument("--inverse-dynamics-learning-rate", type=float, default=1e-3)
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    udpo_kwargs = dict(
        planner_coef=args.planner_coef,
        plan_target=args.plan_target,
        inverse_dynamics_interval=args.inverse_dynamics_interval,
        inverse_dynamics_gradient_steps=args.inverse_dynamics_gradient_steps,
        inverse_dynamics_learning_rate=args.inverse_dynamics_learning_rate,
    )
    print(f"env={args.env} steps={args.steps} udpo_kwargs={udpo_kwargs}")
    ratios = []
    for seed in args.seeds:
        models = {algo: make_model(algo, args.env, seed, udpo_kwargs) for algo in ("udpo", "sac")}
        train_seconds = dict.fromkeys(models, 0.0)
        while models["sac"].num_timesteps < args.steps:
            for algo, model in models.items():
                start = time.perf_counter()
                model.learn(args.eval_every, reset_num_timesteps=False)
                train_seconds[algo] += time.perf_counter() - start
                success = eval_success(model, args.env, args.eval_episodes, seed)
                print(
                    f"seed={seed} algo={algo} steps={model.num_timesteps} eval_success={success:.2f} "
                    f"steps_per_s={model.num_timesteps / train_seconds[algo]:.1f}",
                    flush=True,
                )
        fps = {algo: models[algo].num_timesteps / train_seconds[algo] for algo in models}
        ratios.append(fps["udpo"] / fps["sac"])
        print(f"seed={seed} UDPO {fps['udpo']:.1f} steps/s, SAC {fps['sac']:.1f} steps/s, ratio {ratios[-1]:.2f}")
    print(f"mean UDPO/SAC steps/s ratio over seeds {args.seeds}: {np.mean(ratios):.2f}")


if __name__ == "__main__":
    main()
