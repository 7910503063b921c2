"""
Where the time of an image stage goes: the Vec-to-Image target (pixel-only SAC + HER with ``PixelGoalSACPolicy`` on
``Pilot/FetchReachImage-v0``, the challenge's ``cpu`` settings: batch 64, lr 1e-3, gamma 0.95, 64x64 heads, NatureCNN)
under SB3's ``SAC`` and the package's ``LeanSAC``, timed part by part in one process:

- env step with its 64x64 rendering, beside ``FetchReach-v4``'s step without one (the rendering's share);
- acting: ``predict`` on one frame (one encoder forward);
- HER sampling of a batch (image copies, relabelling);
- a gradient step without its sampling (encoder forward and backward, actor and critics);
- the encoder alone on a batch: forward, and forward + backward.

Usage::

    MUJOCO_GL=osmesa python -m benchmarks.image_split [--repeats 200]
"""

import argparse
import time
from collections.abc import Callable

import gymnasium as gym
import gymnasium_robotics
import numpy as np
import torch as th
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.env_util import make_vec_env

from sb3_pilot.common import PixelGoalSACPolicy
from sb3_pilot.sac import LeanSAC

gym.register_envs(gymnasium_robotics)
ENV_ID = "Pilot/FetchReachImage-v0"
SETTINGS = dict(
    buffer_size=20_000,
    batch_size=64,
    gamma=0.95,
    learning_rate=1e-3,
    learning_starts=500,
    replay_buffer_class=HerReplayBuffer,
    replay_buffer_kwargs=dict(goal_selection_strategy="future", n_sampled_goal=4),
)


def ms_per_call(function: Callable[[], object], repeats: int) -> float:
    """Median of 5 rounds of ``repeats`` calls, in milliseconds per call."""
    rounds = []
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(repeats):
            function()
        rounds.append((time.perf_counter() - start) / repeats * 1e3)
    return float(np.median(rounds))


def env_step_ms(env_id: str, repeats: int) -> float:
    env = gym.make(env_id)
    env.reset(seed=0)

    def step() -> None:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()

    return ms_per_call(step, repeats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=200, help="calls per timing round (5 rounds, median)")
    args = parser.parse_args()
    th.set_num_threads(1)
    print(f"command: python -m benchmarks.image_split --repeats {args.repeats}")
    print(f"env step, {ENV_ID} (64x64 render): {env_step_ms(ENV_ID, args.repeats):.2f} ms")
    print(f"env step, FetchReach-v4 (no render): {env_step_ms('FetchReach-v4', args.repeats):.2f} ms")
    for algo in (SAC, LeanSAC):
        env = make_vec_env(ENV_ID, seed=0)
        model = algo(PixelGoalSACPolicy, env, seed=0, policy_kwargs=dict(net_arch=[64, 64]), **SETTINGS)
        model.learn(600)
        obs = model.env.reset()
        buffer, batch_size = model.replay_buffer, model.batch_size
        sample_ms = ms_per_call(lambda: buffer.sample(batch_size, env=model._vec_normalize_env), args.repeats)  # noqa: B023
        predict_ms = ms_per_call(lambda: model.predict(obs, deterministic=False), args.repeats)  # noqa: B023
        update_ms = ms_per_call(lambda: model.train(1, batch_size), max(args.repeats // 4, 1)) - sample_ms  # noqa: B023
        critic = model.policy.critic
        batch = buffer.sample(batch_size).observations

        def encode() -> th.Tensor:
            return critic.extract_features(batch, critic.features_extractor)  # noqa: B023 (uint8 frames to [0, 1] too)

        with th.no_grad():
            forward_ms = ms_per_call(encode, args.repeats)
        backward_ms = ms_per_call(lambda: encode().sum().backward(), max(args.repeats // 4, 1))
        print(
            f"{algo.__name__}: predict {predict_ms:.2f} ms, HER sample of {batch_size} {sample_ms:.2f} ms, "
            f"gradient step without sampling {update_ms:.2f} ms; encoder on {batch_size} frames: forward {forward_ms:.2f} ms, "
            f"forward + backward {backward_ms:.2f} ms",
            flush=True,
        )


if __name__ == "__main__":
    main()
