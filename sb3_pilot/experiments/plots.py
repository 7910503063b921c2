"""
Pictures of a challenge run: ``python -m sb3_pilot.experiments.plots runs/<challenge> [more folders]``.

Reads ``summary.json`` (written by ``python -m sb3_pilot.experiments.challenges``) and writes, next to it:

- ``success.png``: success rate vs env steps on the target task, per method the interquartile mean over seeds and its
  stratified-bootstrap 95% interval at each evaluation (``rliable``; under 4 seeds the IQM cuts none: the mean),
  the legend giving the IQM of the area under the success curve with its interval (a zero-shot method, evaluated
  after 0 target steps, is a horizontal line), and beside it the final distance to the goal of the same evaluations
  (mean, min-max band), where they recorded it;
- ``plan_error.png``: UDPO's ``rollout/plan_error`` (mean squared error between the planned and the reached next
  state, the paper's "pred-real MSE") over training, from each UDPO stage's ``progress.csv``;
- ``landmarks.png`` (challenges with a planner distilled on ``Pilot/Maze2D-v0``): the paper's Fig. 1 analogue,
  the U-maze's walls, start, goal, the achieved path and the planner's landmarks, for a point in Maze2D that moves
  towards each landmark and, when the challenge has a guidance stage, for the guided Ant in Ant-Maze.
"""

from __future__ import annotations

import argparse
import csv
import json
import textwrap
from pathlib import Path
from typing import Any

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import numpy as np
from matplotlib import pyplot as plt
from matplotlib.axes import Axes
from matplotlib.patches import Circle, Rectangle

from sb3_pilot.distill import GoalPlanner
from sb3_pilot.envs import UMAZE_MAP, UMAZE_SCALING, register_envs, umaze_cell_to_xy
from sb3_pilot.envs.maze import MAZE_DISTANCE_THRESHOLD
from sb3_pilot.experiments.statistics import aggregate_name, method_statistics, pointwise_iqm

MAZE_SOURCE = "Pilot/Maze2D-v0"


def plot_success(summary: dict[str, Any], path: Path) -> None:
    """
    Success rate vs env steps on the target task: per method, the IQM over seeds and its 95% interval at each
    evaluation, labelled with the IQM [95% interval] of the area under the success curve; beside it, where the
    evaluations recorded it, the final distance to the goal (mean over the evaluation's episodes), mean and min-max
    band over seeds.

    :param summary: a challenge's ``summary.json``
    :param path: the PNG to write
    """
    with_distance = any("final_distance" in result["mean"] for result in summary["methods"].values())
    fig, axes = plt.subplots(1, 2 if with_distance else 1, figsize=(12 if with_distance else 7, 4.5), squeeze=False)
    last_step = max(max(result["mean"]["timesteps"]) for result in summary["methods"].values())
    for ax, key in zip(axes[0], ("success_rate", "final_distance")[: axes.shape[1]], strict=True):
        for method, result in summary["methods"].items():
            if key not in result["mean"]:
                ax.plot([], [])  # keeps each method's colour the same in both panels
                continue
            n_points = len(result["mean"]["timesteps"])
            values = np.array([run[key][:n_points] for run in result["runs"]])
            steps = np.array(result["mean"]["timesteps"])
            if n_points == 1:  # zero-shot: evaluated after 0 target steps
                steps = np.array([0, last_step])
                values = np.repeat(values, 2, axis=1)
            if key == "success_rate":
                center, (low, high) = pointwise_iqm(values)
                stats = method_statistics(result["runs"])
                area = stats["area"]
                label = f"{method}\narea {stats['aggregate']} {area['value']:.2f} [{area['ci'][0]:.2f}, {area['ci'][1]:.2f}]"
            else:
                center, low, high, label = values.mean(axis=0), values.min(axis=0), values.max(axis=0), method
            (line,) = ax.plot(steps, center, label=label, linestyle="--" if n_points == 1 else "-")
            ax.fill_between(steps, low, high, color=line.get_color(), alpha=0.2)
        ax.set_xlabel(f"env steps on {summary['target_env']}")
        ax.grid(alpha=0.3)
    axes[0, 0].set(ylabel="evaluation success rate", ylim=(-0.03, 1.03))
    if with_distance:
        axes[0, 1].set(ylabel="final distance to the goal (mean over episodes)", ylim=(0, None))
    seeds = summary["seeds"]
    fig.suptitle(
        "\n".join(
            textwrap.wrap(f"{summary['challenge']} ({summary['budget']}, {len(seeds)} seeds): {summary['description']}", 110)
        ),
        fontsize=9,
    )
    aggregate = aggregate_name(min(len(result["runs"]) for result in summary["methods"].values()))
    title = f"{'IQM' if aggregate == 'IQM' else 'mean (IQM of under 4 seeds)'} over seeds, band: its 95% bootstrap interval"
    axes[0, 0].legend(fontsize=7, title=title, title_fontsize=7)
    _save(fig, path)


def read_progress_csv(path: Path, key: str) -> tuple[np.ndarray, np.ndarray]:
    """
    :param path: an SB3 ``progress.csv``
    :param key: a logged key, e.g. ``rollout/plan_error``
    :return: ``time/total_timesteps`` and ``key`` on the rows where ``key`` was logged
    """
    steps, values = [], []
    with path.open() as file:
        for row in csv.DictReader(file):
            if row.get(key):
                steps.append(float(row["time/total_timesteps"]))
                values.append(float(row[key]))
    return np.array(steps), np.array(values)


def plot_plan_error(summary: dict[str, Any], run_dir: Path, path: Path) -> bool:
    """
    UDPO's plan error (``rollout/plan_error``) over training, one line per UDPO stage and seed.

    :param summary: a challenge's ``summary.json``
    :param run_dir: the folder holding it
    :param path: the PNG to write
    :return: whether a stage logged a plan error (no PNG otherwise)
    """
    curves: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    for key, stage in summary["stages"].items():
        if stage["progress_csv"] is None or not (run_dir / stage["progress_csv"]).exists():  # models/ not kept
            continue
        steps, errors = read_progress_csv(run_dir / stage["progress_csv"], "rollout/plan_error")
        if len(steps) > 0:
            curves.setdefault(key.split("/", 1)[1], []).append((steps, errors))
    if not curves:
        return False
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for index, (stage_name, runs) in enumerate(curves.items()):
        for run, (steps, errors) in enumerate(runs):
            label = f"{stage_name} ({_stage_env(summary, stage_name)}, {len(runs)} seeds)" if run == 0 else None
            ax.plot(steps, errors, color=f"C{index}", alpha=0.7, label=label)
    ax.set(xlabel="env steps", ylabel="plan error: MSE(planned, reached next state)", yscale="log")
    ax.set_title(f"{summary['challenge']}: UDPO's state planner, planned vs reached", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    _save(fig, path)
    return True


def _stage_env(summary: dict[str, Any], stage_name: str) -> str:
    """The task of a zoo stage, read from its recorded zoo command line."""
    zoo = next(stage["config"].get("zoo", []) for key, stage in summary["stages"].items() if key.endswith(f"/{stage_name}"))
    return zoo[zoo.index("--env") + 1] if "--env" in zoo else "?"


def draw_umaze(
    ax: Axes,
    achieved_goals: np.ndarray,
    landmarks: np.ndarray,
    desired_goal: np.ndarray,
    title: str,
    imagined: np.ndarray | None = None,
) -> None:
    """
    The U-maze's walls, start, goal (its success radius), the achieved path and the landmarks.

    :param ax: the axes
    :param achieved_goals: achieved xy of an episode, shape (n, 2)
    :param landmarks: landmarks shown along it, shape (m, 2)
    :param desired_goal: the real goal
    :param title: the axes' title
    :param imagined: landmarks chained by the planner from the start alone (its imagined path), shape (k, 2)
    """
    half = UMAZE_SCALING / 2
    for row, cells in enumerate(UMAZE_MAP):
        for col, wall in enumerate(cells):
            if wall:
                x, y = umaze_cell_to_xy((row, col))
                ax.add_patch(Rectangle((x - half, y - half), UMAZE_SCALING, UMAZE_SCALING, color="0.3"))
    ax.add_patch(Circle(tuple(desired_goal), MAZE_DISTANCE_THRESHOLD, color="tab:green", alpha=0.3))
    if imagined is not None:
        ax.plot(*imagined.T, ":", color="tab:purple", lw=1.5, label="imagined path (chained from the start)")
    ax.plot(*landmarks.T, "o", mfc="none", color="tab:orange", ms=6, label="landmark shown at each step")
    ax.plot(*achieved_goals.T, "-", color="tab:blue", lw=1.5, label="achieved path")
    ax.plot(*achieved_goals[0], "o", color="tab:blue", ms=9, label="start")
    ax.plot(*desired_goal, "*", color="tab:green", ms=15, label="goal")
    limit = len(UMAZE_MAP) * half
    ax.set(xlim=(-limit, limit), ylim=(-limit, limit), aspect="equal", title=title)
    ax.title.set_fontsize(9)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=2)


def maze2d_rollout(planner: GoalPlanner, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    One Maze2D episode of a point that steps towards the planner's landmark at each step (the maze's walls decide
    where it really goes).

    :param planner: a goal planner distilled on ``Pilot/Maze2D-v0``
    :param seed: the episode's reset seed
    :return: achieved goals (steps + 1, 2), landmarks (steps, 2), goal (2,)
    """
    register_envs()
    env = gym.make(MAZE_SOURCE)
    observation, _ = env.reset(seed=seed)
    step_size = env.unwrapped.step_size  # type: ignore[attr-defined]
    achieved, landmarks = [observation["achieved_goal"]], []
    done = False
    while not done:
        landmark = planner.predict(observation["achieved_goal"], observation["desired_goal"])
        observation, _, terminated, truncated, _ = env.step((landmark - observation["achieved_goal"]) / step_size)
        achieved.append(observation["achieved_goal"])
        landmarks.append(landmark)
        done = terminated or truncated
    return np.array(achieved), np.array(landmarks), observation["desired_goal"]


def plot_landmarks(summary: dict[str, Any], run_dir: Path, path: Path) -> bool:
    """
    The paper's Fig. 1 analogue for the first seed's Maze2D planner: a Maze2D rollout following its landmarks and,
    if the challenge has a guidance stage, the guided Ant's first episode.

    :param summary: a challenge's ``summary.json``
    :param run_dir: the folder holding it
    :param path: the PNG to write
    :return: whether the challenge has a Maze2D planner (no PNG otherwise)
    """
    seed_dir = run_dir / "models" / f"seed_{summary['seeds'][0]}"
    # the guided evaluations (an unguided one has no planner, no landmarks)
    results = [json.loads(file.read_text()) for file in sorted(seed_dir.glob("*/guidance.json"))]
    results = [result for result in results if result.get("planner")]
    # the planners the challenge distilled, else the one its guidance read (``--reuse-shipped``: the shipped one)
    files = sorted(seed_dir.glob("*/planner.pt")) or [Path(result["planner"]) for result in results]
    planners = [planner for planner in map(GoalPlanner.load, files) if planner.source_task == MAZE_SOURCE]
    if not planners:
        return False
    guided = [result["episodes"][0] for result in results]
    fig, axes = plt.subplots(1, 1 + len(guided), figsize=(5 * (1 + len(guided)), 5), squeeze=False)
    achieved, landmarks, goal = maze2d_rollout(planners[0], seed=summary["seeds"][0])
    imagined = planners[0].plan(achieved[0], goal, horizon=len(landmarks))
    title = "Maze2D: a point stepping to the distilled planner's landmarks"
    draw_umaze(axes[0, 0], achieved, landmarks, goal, title, imagined=imagined)
    for ax, episode in zip(axes[0, 1:], guided, strict=True):
        draw_umaze(
            ax,
            np.array(episode["achieved_goals"]),
            np.array(episode["landmarks"]),
            np.array(episode["desired_goal"]),
            "Ant-Maze, zero-shot: the Ant controller guided by the landmarks",
        )
    _save(fig, path)
    return True


def _save(fig: plt.Figure, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    print(f"Saved {path}")


def plot_challenge(run_dir: str | Path) -> list[Path]:
    """
    Write the PNGs of a challenge run next to its ``summary.json``.

    :param run_dir: ``<root>/<challenge>``
    :return: the PNGs written
    """
    run_dir = Path(run_dir)
    summary = json.loads((run_dir / "summary.json").read_text())
    written = [run_dir / "success.png"]
    plot_success(summary, written[0])
    if plot_plan_error(summary, run_dir, run_dir / "plan_error.png"):
        written.append(run_dir / "plan_error.png")
    if plot_landmarks(summary, run_dir, run_dir / "landmarks.png"):
        written.append(run_dir / "landmarks.png")
    return written


def main(argv: list[str] | None = None) -> None:
    """``python -m sb3_pilot.experiments.plots RUN_DIR [RUN_DIR ...]``."""
    parser = argparse.ArgumentParser(prog="python -m sb3_pilot.experiments.plots", description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dirs", nargs="+", help="challenge folders holding a summary.json (runs/<challenge>)")
    for run_dir in parser.parse_args(argv).run_dirs:
        plot_challenge(run_dir)


if __name__ == "__main__":
    main()
