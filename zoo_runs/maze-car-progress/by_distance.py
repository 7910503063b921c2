"""
Which goals are left when Maze-Car's agents pass 50%: success by the length of the shortest path from start to goal,
for SAC+HER and HER+PILoT (planned progress), at checkpoints of the first 16k steps.

The stages' zoo commands of ``run.py`` (seeds 0-2, the same arguments but ``-n 16000`` and a checkpoint every 4000
steps), then every checkpoint played for ``--episodes`` deterministic episodes of ``Pilot/Maze2DCar-v0`` (uniform starts
and goals, as its evaluations), each episode's path length from ``UMazeOraclePlanner.shortest_path``.

    OMP_NUM_THREADS=1 python zoo_runs/maze-car-progress/by_distance.py > zoo_runs/maze-car-progress/by_distance.md
"""

from __future__ import annotations

import argparse
import itertools
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
from stable_baselines3 import SAC
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_pilot.envs import register_envs
from sb3_pilot.experiments.benchmarks.oracle_landmarks import UMazeOraclePlanner

PLANNER = Path(__file__).parents[1] / "zero-shot-ant-maze/controller/maze2d_planner.pt"
BONUS = {"planner": str(PLANNER), "beta": 1.0, "similarity": "planned_progress"}
#: method: its stage's YAML and extra ``-params``
METHODS = {
    "SAC+HER": ("cpu/sac.yml", []),
    "HER+PILoT (planned progress)": ("cpu/sac_pilot.yml", [f"env_wrapper:[{{'sb3_pilot.PilotBonusWrapper': {BONUS!r}}}]"]),
}
BINS = (0.0, 6.0, 12.0, 18.0, np.inf)  # shortest-path length from start to goal (world units; 0.5 a car step at most)


def train(method: str, seed: int, folder: Path, steps: int, every: int) -> Path:
    """Run the stage's zoo command (checkpoints every ``every`` steps); return its log folder."""
    conf, params = METHODS[method]
    command = [sys.executable, "-m", "sb3_pilot.experiments.zoo", "train", "--algo", "sac", "--env", "Pilot/Maze2DCar-v0"]
    command += ["--conf-file", conf, "-f", str(folder), "--seed", str(seed), "-n", str(steps), "--num-threads", "1"]
    command += ["--save-freq", str(every), "-params", "buffer_size:40000", "policy_kwargs:{'net_arch': [64, 64]}", *params]
    subprocess.run(command, check=True, capture_output=True)
    return next(folder.glob("sac/Pilot-Maze2DCar-v0_*"))


def play(model_path: Path, episodes: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Path lengths start -> goal and final-step success of ``episodes`` deterministic episodes."""
    env = gym.make("Pilot/Maze2DCar-v0")
    model = SAC.load(model_path, env=DummyVecEnv([lambda: gym.make("Pilot/Maze2DCar-v0")]), device="cpu")
    starts, goals, successes = [], [], []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed * 100_000 + episode)
        starts.append(obs["achieved_goal"])
        goals.append(obs["desired_goal"])
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(model.predict(obs, deterministic=True)[0])
            done = terminated or truncated
        successes.append(info["is_success"])
    _, lengths = UMazeOraclePlanner().shortest_path(np.array(starts, dtype=np.float64), np.array(goals, dtype=np.float64))
    return lengths, np.array(successes, dtype=float)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=16_000)
    parser.add_argument("--every", type=int, default=4000)
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--folder", type=Path, default=Path(__file__).parent / "by_distance" / "models")
    args = parser.parse_args()
    register_envs()
    labels = [f"{low:.0f}-{high:.0f}" if np.isfinite(high) else f">= {low:.0f}" for low, high in itertools.pairwise(BINS)]
    print(f"Success by shortest-path length start -> goal (world units), seeds 0-{args.seeds - 1}, {args.episodes} episodes")
    print("per checkpoint and seed (the same episodes for every checkpoint); the fraction of episodes per bin in brackets.\n")
    print(f"| method | env steps | {' | '.join(labels)} | all |")
    print(f"|---|---|{'---|' * len(labels)}---|")
    for method in METHODS:
        results: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        for seed in range(args.seeds):
            folder = args.folder / method.split()[0].replace("+", "_") / f"seed_{seed}"
            log = train(method, seed, folder, args.steps, args.every)
            for step in range(args.every, args.steps + 1, args.every):
                results.setdefault(step, []).append(play(log / f"rl_model_{step}_steps.zip", args.episodes, seed))
        for step, runs in results.items():
            lengths, successes = (np.concatenate(parts) for parts in zip(*runs, strict=True))
            which = np.digitize(lengths, BINS[1:-1])
            cells = [f"{successes[which == b].mean():.2f} ({np.mean(which == b):.2f})" for b in range(len(labels))]
            print(f"| {method} | {step} | {' | '.join(cells)} | {successes.mean():.2f} |")


if __name__ == "__main__":
    main()
