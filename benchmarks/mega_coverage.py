"""
MEGA's behaviour, not only its success: how fast SAC + HER + MEGA covers ``Pilot/Maze2D-v0`` (far goal) beside SAC + HER,
same hyperparameters (the ``cpu`` preset's Maze2D entry) and seeds::

    python -m benchmarks.mega_coverage --seeds 0 1 2 --steps 25000 --out zoo_runs/mega

Measured per run, from the training transitions (the replay buffer, in order) and from evaluations on the env's goal:

- coverage: the share of the maze's free area visited, on a grid of 1 x 1 unit cells over the U's 7 free 4 x 4
  cells (112 cells), after every ``--every`` steps;
- first step whose achieved goal lies in the far goal's cell (3, 1), where the env draws its goals;
- evaluation success on the env's goals (``--eval-episodes`` deterministic episodes every ``--every`` steps), and the
  first step it reaches 50%.

Each run is written to ``<out>/seeds/<method>_seed<k>.json`` when it ends (a rerun skips finished runs); then
``coverage.json`` (interquartile means with stratified-bootstrap 95% intervals from ``rliable``) and
``coverage.png``. One torch thread; runs go one after the other.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_pilot.baselines import MegaCallback, MegaGoalWrapper
from sb3_pilot.envs import UMAZE_MAP, UMAZE_SCALING, umaze_cell_to_xy

ENV_ID = "Pilot/Maze2D-v0"
METHODS = ("SAC+HER", "SAC+HER+MEGA")
#: hyperparams/cpu/sac.yml's Pilot/Maze2D-v0 entry (both methods)
SAC_KWARGS: dict[str, Any] = {
    "gamma": 0.99,
    "buffer_size": 100_000,
    "batch_size": 128,
    "learning_rate": 3e-4,
    "replay_buffer_class": HerReplayBuffer,
    "replay_buffer_kwargs": {"goal_selection_strategy": "future", "n_sampled_goal": 4},
}
#: the U-maze's free cells, (row, col) in ``UMAZE_MAP``
FREE_CELLS = tuple((row, col) for row, line in enumerate(UMAZE_MAP) for col, wall in enumerate(line) if not wall)
GOAL_CELL = (3, 1)  # where Pilot/Maze2D-v0's far goal lies (``sample_umaze_start_goal(..., "far")``)
GRID = 1.0  # side of a coverage cell, in world units
_SUBCELLS = int(UMAZE_SCALING / GRID)


def coverage_cells(xy: np.ndarray) -> np.ndarray:
    """
    :param xy: positions in the U-maze, shape (n, 2)
    :return: for each, the index of its 1 x 1 coverage cell among the free area's ``7 * 16``, or -1 outside
    """
    index = np.full(len(xy), -1)
    for k, cell in enumerate(FREE_CELLS):
        low = umaze_cell_to_xy(cell) - UMAZE_SCALING / 2
        sub = np.floor((xy - low) / GRID).astype(int)
        inside = np.all((sub >= 0) & (sub <= _SUBCELLS), axis=1) & (index < 0)
        sub = np.minimum(sub, _SUBCELLS - 1)  # a point on the far face belongs to the last row / column
        index[inside] = k * _SUBCELLS**2 + sub[inside, 0] * _SUBCELLS + sub[inside, 1]
    return index


def coverage_curve(achieved: np.ndarray, checkpoints: np.ndarray) -> np.ndarray:
    """
    :param achieved: the achieved goals of the training transitions, in order, shape (steps, 2)
    :param checkpoints: step counts
    :return: the share of coverage cells visited within the first ``checkpoint`` steps, for each checkpoint
    """
    cells = coverage_cells(achieved)
    n_cells = len(FREE_CELLS) * _SUBCELLS**2
    first_visit = np.full(n_cells, np.inf)
    steps = np.arange(1, len(cells) + 1)
    valid = cells >= 0
    np.minimum.at(first_visit, cells[valid], steps[valid])
    return np.array([np.mean(first_visit <= checkpoint) for checkpoint in checkpoints])


def first_step_in_goal_cell(achieved: np.ndarray) -> int | None:
    """The first training step whose achieved goal lies in the far goal's cell (None if none does)."""
    offset = np.abs(achieved - umaze_cell_to_xy(GOAL_CELL))
    hits = np.flatnonzero(np.all(offset <= UMAZE_SCALING / 2, axis=1))
    return int(hits[0]) + 1 if len(hits) else None


def run(method: str, seed: int, steps: int, every: int, eval_episodes: int, eval_log: Path) -> dict[str, Any]:
    """
    Train one method on one seed and measure it.

    :param method: one of ``METHODS``
    :param seed: the seed
    :param steps: training steps
    :param every: steps between measurements
    :param eval_episodes: evaluation episodes (env goals, deterministic) per measurement
    :param eval_log: folder of the evaluations' ``evaluations.npz`` (``EvalCallback``'s)
    :return: the run's curves and summary numbers
    """
    env = DummyVecEnv([lambda: gym.make(ENV_ID)])
    callbacks: list[Any] = []
    if method == "SAC+HER+MEGA":
        env = MegaGoalWrapper(env)
        callbacks.append(MegaCallback())
    env.seed(seed)
    eval_env = DummyVecEnv([lambda: gym.make(ENV_ID)])
    if method == "SAC+HER+MEGA":
        eval_env = MegaGoalWrapper(eval_env)  # as the RL Zoo wraps it: no callback attached, so the env's goals
    eval_env.seed(10_000 + seed)
    evaluation = EvalCallback(eval_env, n_eval_episodes=eval_episodes, eval_freq=every, log_path=str(eval_log), verbose=0)
    model = SAC("MultiInputPolicy", env, seed=seed, verbose=0, **SAC_KWARGS)
    start = time.time()
    model.learn(steps, callback=[*callbacks, evaluation])
    wall = time.time() - start
    achieved = model.replay_buffer.next_observations["achieved_goal"][:steps, 0]
    checkpoints = np.arange(every, steps + 1, every)
    success = np.array([np.mean(result) for result in evaluation.evaluations_successes])
    reached = np.flatnonzero(success >= 0.5)
    return {
        "method": method,
        "seed": seed,
        "steps": checkpoints.tolist(),
        "coverage": coverage_curve(achieved, checkpoints).tolist(),
        "eval_steps": [int(step) for step in evaluation.evaluations_timesteps],
        "eval_success": success.tolist(),
        "first_step_in_goal_cell": first_step_in_goal_cell(achieved),
        "first_eval_success_50": int(evaluation.evaluations_timesteps[reached[0]]) if len(reached) else None,
        "wall_s": round(wall, 1),
    }


def interval(scores: np.ndarray) -> dict[str, float]:
    """
    :param scores: one score per seed
    :return: interquartile mean and its stratified-bootstrap 95% interval (``rliable``)
    """
    from rliable import library, metrics

    point, bounds = library.get_interval_estimates(
        {"m": scores[:, None]}, lambda x: np.array([metrics.aggregate_iqm(x)]), reps=5000
    )
    return {"iqm": float(point["m"][0]), "low": float(bounds["m"][0, 0]), "high": float(bounds["m"][1, 0])}


def difference(her: np.ndarray, mega: np.ndarray, reps: int = 5000) -> dict[str, float]:
    """
    :param her: SAC + HER's scores, one per seed
    :param mega: SAC + HER + MEGA's scores, one per seed
    :return: the IQM difference MEGA - HER and its 95% interval, from a bootstrap that resamples each method's seeds
        independently (stratified, as ``rliable``'s; computed here, since rliable's intervals are per method)
    """
    from rliable.metrics import aggregate_iqm

    rng = np.random.default_rng(0)
    draws = [aggregate_iqm(rng.choice(mega, len(mega))) - aggregate_iqm(rng.choice(her, len(her))) for _ in range(reps)]
    low, high = np.percentile(draws, [2.5, 97.5])
    return {"iqm": float(aggregate_iqm(mega) - aggregate_iqm(her)), "low": float(low), "high": float(high)}


def per_seed_scores(runs: list[dict[str, Any]], steps: int) -> dict[str, np.ndarray]:
    """The scores compared, one per run (steps never reached counted as ``steps``)."""
    coverage = np.array([r["coverage"] for r in runs])
    scores = {"final_coverage": coverage[:, -1], "mean_coverage_over_training": coverage.mean(axis=1)}
    for key in ("first_step_in_goal_cell", "first_eval_success_50"):
        scores[key] = np.array([steps if r[key] is None else r[key] for r in runs], dtype=float)
    scores["final_eval_success"] = np.array([r["eval_success"][-1] for r in runs])
    return scores


def summarize(runs: list[dict[str, Any]], steps: int) -> dict[str, Any]:
    """Per method: the IQM coverage curve with intervals, and the summary numbers (unreached counted as ``steps``)."""
    summary: dict[str, Any] = {}
    for method in METHODS:
        mine = [r for r in runs if r["method"] == method]
        if not mine:
            continue
        coverage = np.array([r["coverage"] for r in mine])
        summary[method] = {
            "seeds": [r["seed"] for r in mine],
            "steps": mine[0]["steps"],
            "coverage_curve": [interval(coverage[:, k]) for k in range(coverage.shape[1])],
        }
        for key, scores in per_seed_scores(mine, steps).items():
            summary[method][key] = {**interval(scores), "per_seed": [round(float(score), 4) for score in scores]}
        summary[method]["wall_s"] = [r["wall_s"] for r in mine]
    return summary


def plot(summary: dict[str, Any], path: Path) -> None:
    """Coverage (IQM, 95% interval) against training steps, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6, 4))
    for method, result in summary.items():
        curve = result["coverage_curve"]
        axis.plot(result["steps"], [c["iqm"] for c in curve], label=f"{method} ({len(result['seeds'])} seeds)")
        axis.fill_between(result["steps"], [c["low"] for c in curve], [c["high"] for c in curve], alpha=0.25)
    axis.set(xlabel="training steps", ylabel="free cells visited (share)", title=f"{ENV_ID}, far goal: coverage")
    axis.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=25_000)
    parser.add_argument("--every", type=int, default=2500)
    parser.add_argument("--eval-episodes", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("runs/mega"))
    args = parser.parse_args()
    th.set_num_threads(1)
    command = "python -m benchmarks.mega_coverage " + (
        f"--seeds {' '.join(map(str, args.seeds))} --steps {args.steps} --every {args.every} "
        f"--eval-episodes {args.eval_episodes} --out {args.out}"
    )
    print(command, flush=True)
    runs = []
    for seed in args.seeds:
        for method in METHODS:
            name = f"{method.replace('+', '_')}_seed{seed}"
            path = args.out / "seeds" / f"{name}.json"
            if not path.exists():
                path.parent.mkdir(parents=True, exist_ok=True)
                result = run(method, seed, args.steps, args.every, args.eval_episodes, args.out / "seeds" / f"{name}_eval")
                path.write_text(json.dumps(result, indent=1))
            result = json.loads(path.read_text())
            print(
                f"{method} seed {seed}: coverage {result['coverage'][-1]:.2f}, goal cell at "
                f"{result['first_step_in_goal_cell']}, eval success {result['eval_success'][-1]:.2f} "
                f"(50% at {result['first_eval_success_50']}), {result['wall_s']} s",
                flush=True,
            )
            runs.append(result)
    summary = summarize(runs, args.steps)
    for method, result in summary.items():
        print(method, {key: value for key, value in result.items() if key != "coverage_curve"}, flush=True)
    her, mega = (per_seed_scores([r for r in runs if r["method"] == method], args.steps) for method in METHODS)
    differences = {key: difference(her[key], mega[key]) for key in her}
    print("MEGA - HER (IQM, 95% interval):", differences, flush=True)
    record = {"command": command, "env": ENV_ID, "methods": summary, "mega_minus_her": differences}
    (args.out / "coverage.json").write_text(json.dumps(record, indent=1))
    plot(summary, args.out / "coverage.png")


if __name__ == "__main__":
    main()
