"""
Cost of PilotBonusWrapper: SAC + HER training steps/s on a wrapped task relative to the same training unwrapped.

Both models are built once and trained in alternating chunks in the same process (so machine load hits both
alike); the ratio is wrapped steps/s over unwrapped steps/s. The wrapped run uses PilotHerReplayBuffer and an
untrained goal planner (default: the default distillation size; its weights do not change its cost).

    python -m benchmarks.bonus_overhead --env Pilot/Maze2D-v0 --rounds 4 --chunk 1000
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
from stable_baselines3 import SAC, HerReplayBuffer

from sb3_pilot.distill import GoalPlanner
from sb3_pilot.envs import register_envs
from sb3_pilot.transfer import SIMILARITIES, PilotBonusWrapper, PilotHerReplayBuffer


def make_sac(env: gym.Env, replay_buffer_class: type[HerReplayBuffer], seed: int) -> SAC:
    """SAC + HER with RL-Zoo's FetchReach settings (64x64 nets, gamma 0.95, lr 1e-3, batch 256)."""
    return SAC(
        "MultiInputPolicy",
        env,
        replay_buffer_class=replay_buffer_class,
        replay_buffer_kwargs={"n_sampled_goal": 4, "goal_selection_strategy": "future"},
        learning_starts=1000,
        batch_size=256,
        gamma=0.95,
        learning_rate=1e-3,
        policy_kwargs={"net_arch": [64, 64]},
        seed=seed,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", default="Pilot/Maze2D-v0", help="goal task to train on")
    parser.add_argument("--rounds", type=int, default=4, help="timed chunks per variant")
    parser.add_argument("--chunk", type=int, default=1000, help="env steps per timed chunk")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--planner-net-arch", type=int, nargs="+", default=[256, 256], help="hidden layers of the planner")
    parser.add_argument("--similarity", choices=SIMILARITIES, default="displacement_cosine", help="the bonus's similarity")
    args = parser.parse_args()
    register_envs()

    env = gym.make(args.env)
    goal_dim = env.observation_space["desired_goal"].shape[0]
    planner = GoalPlanner(goal_dim, args.planner_net_arch, metadata={"source_task": args.env})
    models = {
        "plain": make_sac(env, HerReplayBuffer, args.seed),
        "bonus": make_sac(
            PilotBonusWrapper(gym.make(args.env), planner, similarity=args.similarity), PilotHerReplayBuffer, args.seed
        ),
    }
    seconds = dict.fromkeys(models, 0.0)
    for model in models.values():
        model.learn(models["plain"].learning_starts + args.chunk)  # untimed warm-up, past the random phase
    for _ in range(args.rounds):
        for name, model in models.items():
            start = time.perf_counter()
            model.learn(args.chunk, reset_num_timesteps=False)
            seconds[name] += time.perf_counter() - start
    speed = {name: args.rounds * args.chunk / value for name, value in seconds.items()}
    ratio = speed["bonus"] / speed["plain"]
    print(
        f"{args.env}, {args.similarity}: unwrapped {speed['plain']:.1f} steps/s, wrapped {speed['bonus']:.1f} steps/s, "
        f"ratio {ratio:.3f}"
    )


if __name__ == "__main__":
    main()
