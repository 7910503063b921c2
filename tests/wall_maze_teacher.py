"""
Does a teacher learn to go around the wall of ``WallMazeEnv`` (``Pilot/WallMaze2D-v0``'s point as the tests build it,
``tests/maze_envs.py``; ``test_wall_maze_landmarks_go_around_the_wall``)?
UDPO (``UDPO_SETTINGS``, arguments over them with ``--udpo-kwargs``) and SAC + HER, both with ``SMALL_HER_SETTINGS``,
evaluated every ``--eval-every`` steps on the cross-wall goals of four start/goal pairs below the gap (deterministic
actions once, where each episode ends, sampled actions 5 times), with facts about the training episodes since the last
evaluation: cross-wall episodes (won), paths from below the gap on one side to below it on the other, the cross-wall
share of the HER ``future`` pairs, blocked moves. ``--landmarks`` also distils a goal planner (the test's student by
default) and prints where its landmark path from (-0.5, -0.6) to (0.5, -0.6) crosses ``x = 0``, snapped and not.

Measured (``zoo_runs/landmarks/logs/wall_maze_teacher_*.log``, before UDPO's default became 1e-3 in
``zoo_runs/sources/lambda``): with the paper's ``planner_coef=1e-2`` UDPO does not
learn the detour in 20k steps (0/4 deterministic on seeds 0-2; sampled actions 0-18/20, unstable), SAC + HER with the
same settings does by 12k on seeds 0-2 (4/4, 19-20/20). UDPO with ``planner_coef=0`` does (3/4 by 12k-16k on seeds
0-2), and the landmarks distilled from it go around with a [256, 256] student (5000 gradient steps), not with a
[64, 64] one (2000 steps) that cuts through the thin wall. Usage (repository root)::

    OMP_NUM_THREADS=1 python tests/wall_maze_teacher.py --steps 16000 --eval-every 4000 [--seed 0] [--no-sac]
        [--landmarks] [--udpo-kwargs "{'planner_coef': 0.0}"] [--env-kwargs "{'slide': True}"] [--gap-y 0.0]
"""

import argparse
import ast
import functools
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from maze_envs import SMALL_HER_SETTINGS, UDPO_SETTINGS, WallMazeEnv, wall_crossing_y, wall_landmark_path
from stable_baselines3 import SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor

from sb3_pilot import UDPO
from sb3_pilot.distill import distill_goal_planner

PAIRS = [((-0.5, -0.6), (0.5, -0.6)), ((0.5, -0.6), (-0.5, -0.6)), ((-0.5, -0.3), (0.6, -0.8)), ((-0.7, -0.8), (0.3, -0.5))]


def cross_wall_successes(
    model: BaseAlgorithm, env: WallMazeEnv, deterministic: bool, repeats: int, ends: list | None = None
) -> int:
    """
    :param model: the trained teacher
    :param env: the maze
    :param deterministic: act with the policy's mean
    :param repeats: passes over the four pairs
    :param ends: if given, receives each episode's last position
    :return: how many episodes reached their goal
    """
    wins = 0
    for repeat in range(repeats):
        for start, goal in PAIRS:
            obs, _ = env.reset(seed=repeat, options={"start": start, "goal": goal})
            for _ in range(env.max_episode_steps):
                obs, _, _, _, info = env.step(model.predict(obs, deterministic=deterministic)[0])
                if info["is_success"]:
                    wins += 1
                    break
            if ends is not None:
                ends.append(env.position.round(2).tolist())
    return wins


class Recorder(gym.Wrapper):
    """Keeps every finished training episode: positions (start included), goal, blocked moves."""

    def __init__(self, env: WallMazeEnv):
        super().__init__(env)
        self.episodes: list[dict[str, Any]] = []
        self.positions: list[np.ndarray] = []
        self.blocked = 0

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self.positions, self.blocked = [self.env.unwrapped.position.copy()], 0
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        position = self.env.unwrapped.position.copy()
        self.blocked += int(np.array_equal(position, self.positions[-1]))
        self.positions.append(position)
        if terminated or truncated:
            self.episodes.append(
                {
                    "positions": np.array(self.positions),
                    "goal": self.env.unwrapped.goal.copy(),
                    "blocked": self.blocked,
                    "success": bool(info["is_success"]),
                }
            )
        return obs, reward, terminated, truncated, info


def below(points: np.ndarray, gap_y: float) -> np.ndarray:
    """Side (-1 / +1) of the points below the gap, 0 elsewhere."""
    return np.where(points[..., 1] < gap_y, np.sign(points[..., 0]), 0.0)


def data_facts(episodes: list[dict[str, Any]], gap_y: float) -> str:
    """
    Cross-wall episodes (start and goal below the gap, opposite sides), their success rate, episodes whose path goes
    from below the gap on one side to below it on the other (a detour), the share of HER ``future`` relabelled pairs
    (s_t, achieved g_t' for t' > t) that are cross-wall, and the share of blocked moves.
    """
    cross = detours = cross_wins = pairs = cross_pairs = blocked = steps = 0
    for episode in episodes:
        sides = below(episode["positions"], gap_y)
        start_side, goal_side = sides[0], below(episode["goal"], gap_y)
        if start_side != 0 and goal_side == -start_side:
            cross += 1
            cross_wins += episode["success"]
        first = {side: np.flatnonzero(sides == side) for side in (-1.0, 1.0)}
        if any(len(first[s]) and len(first[-s]) and first[s][0] < first[-s][-1] for s in (-1.0, 1.0)):
            detours += 1
        achieved = sides[1:]
        for t in range(len(achieved)):  # s_t = positions[t], future goals achieved[t:]
            if sides[t] != 0:
                cross_pairs += int((achieved[t:] == -sides[t]).sum())
            pairs += len(achieved) - t
        blocked += episode["blocked"]
        steps += len(achieved)
    return (
        f"episodes {len(episodes)}, cross-wall {cross} (won {cross_wins}), paths below-to-below across {detours}, "
        f"cross-wall share of future-relabelled pairs {cross_pairs / max(pairs, 1):.4f}, "
        f"blocked moves {blocked / max(steps, 1):.3f}"
    )


class CrossWallEval(BaseCallback):
    """Evaluates the cross-wall goals (and summarises the new training episodes) every ``eval_every`` steps."""

    def __init__(self, name: str, env_class: Any, recorder: Recorder, eval_every: int, distill_kwargs: dict | None = None):
        super().__init__()
        self.name, self.env_class, self.recorder, self.eval_every = name, env_class, recorder, eval_every
        self.distill_kwargs = distill_kwargs
        self.seen, self.start = 0, time.time()

    def _on_step(self) -> bool:
        if self.num_timesteps % self.eval_every == 0:
            env = self.env_class()
            ends: list = []
            with th.random.fork_rng(devices=[]):  # the evaluation leaves the training's random numbers alone
                deterministic = cross_wall_successes(self.model, env, True, 1, ends)
                sampled = cross_wall_successes(self.model, env, False, 5)
                landmarks = ""
                if self.distill_kwargs is not None:
                    planner = distill_goal_planner(self.model, **self.distill_kwargs, env=Monitor(env))
                    landmarks = (
                        f" | landmarks cross x = 0 at y = {wall_crossing_y(wall_landmark_path(planner, True)):.2f} (snapped), "
                        f"{wall_crossing_y(wall_landmark_path(planner, False)):.2f} (not snapped)"
                    )
            new = self.recorder.episodes[self.seen :]
            self.seen = len(self.recorder.episodes)
            print(
                f"{self.name} {self.num_timesteps} steps ({time.time() - self.start:.0f} s): cross-wall goals "
                f"{deterministic}/4 deterministic (ends {ends}), {sampled}/20 sampled{landmarks} | last "
                f"{self.eval_every} steps: {data_facts(new, env.gap_y)}",
                flush=True,
            )
        return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--eval-every", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--step-size", type=float, default=0.2)
    parser.add_argument("--gap-y", type=float, default=0.0, help="the wall covers y < gap_y")
    parser.add_argument("--episode-steps", type=int, default=30)
    parser.add_argument("--gamma", type=float, default=SMALL_HER_SETTINGS["gamma"])
    parser.add_argument("--learning-starts", type=int, default=SMALL_HER_SETTINGS["learning_starts"])
    parser.add_argument("--net-arch", type=int, nargs="+", default=SMALL_HER_SETTINGS["policy_kwargs"]["net_arch"])
    parser.add_argument("--env-kwargs", default="{}", help="other WallMazeEnv arguments, a Python dict literal")
    parser.add_argument("--udpo-kwargs", default="{}", help="UDPO arguments over UDPO_SETTINGS, a Python dict literal")
    parser.add_argument("--no-sac", action="store_true")
    parser.add_argument("--no-udpo", action="store_true")
    parser.add_argument("--landmarks", action="store_true", help="distil a planner at each evaluation (UDPO only)")
    parser.add_argument(
        "--distill-kwargs",
        default="{'n_samples': 20_000, 'gradient_steps': 5000, 'net_arch': [256, 256]}",
        help="distill_goal_planner arguments of --landmarks (default: the test's), a Python dict literal",
    )
    args = parser.parse_args()
    th.set_num_threads(1)
    env_class = functools.partial(
        WallMazeEnv,
        step_size=args.step_size,
        gap_y=args.gap_y,
        max_episode_steps=args.episode_steps,
        **ast.literal_eval(args.env_kwargs),
    )
    settings = {
        **SMALL_HER_SETTINGS,
        "gamma": args.gamma,
        "learning_starts": args.learning_starts,
        "policy_kwargs": {"net_arch": args.net_arch},
        "seed": args.seed,
    }
    print(f"env {env_class.keywords}, settings {settings}", flush=True)
    algorithms = {}
    if not args.no_udpo:
        algorithms["UDPO"] = functools.partial(UDPO, **{**UDPO_SETTINGS, **ast.literal_eval(args.udpo_kwargs)})
    if not args.no_sac:
        algorithms["SAC+HER"] = SAC
    for name, algorithm in algorithms.items():
        distill_kwargs = ast.literal_eval(args.distill_kwargs) if args.landmarks and name == "UDPO" else None
        recorder = Recorder(env_class())
        model = algorithm("MultiInputPolicy", Monitor(recorder), **settings)
        model.learn(args.steps, callback=CrossWallEval(name, env_class, recorder, args.eval_every, distill_kwargs))


if __name__ == "__main__":
    main()
