"""
Are the walled maze's landmarks in the wall? The raw landmarks (not snapped to the planner's support goals) of goal
planners distilled on ``Pilot/WallMaze2D-v0``, such as the ``wall-maze-car`` challenge's, from its SAC + HER teacher
(``<root>/wall-maze-car/models/seed_<k>/distill/planner.pt``), over a grid of start and goal positions.

Pairs: every ordered pair of distinct positions of an n x n grid over ``[-0.8, 0.8]^2`` where the tasks draw starts and
goals (``WallMaze.off_wall``: none in the wall nor within twice its half width of it below the gap), in three classes:
``across`` (both below the gap, on opposite sides of the wall: a path must go round it through the gap), ``same side``
(both below the gap, on one side) and ``above`` (at least one above the gap). The map is the registered tasks' own.

Per planner and class:

* ``one step``: the landmark ``planner.predict(g, g_target)`` (unsnapped): how many lie inside the wall (``in wall``)
  or outside the square (``out``), and the deepest of them (``depth``: distance to the free space, ``WallMaze.depth``;
  0 on a wall's face);
* ``chained``: ``--horizon`` landmarks, each planned from the previous (``plan(..., snap=False)``): the same counts over
  all of them; ``planned step``, each path's mean step up to its first landmark within the success distance (0.1) of
  the goal (``benchmarks.landmarks.planned_steps``), averaged over the pairs, and ``reached``, the share of paths with
  such a landmark; for ``across`` pairs, ``gap``: the share of paths that reach below the gap on the goal's side with
  no landmark in the wall and no straight segment through it before (round the wall's top), and ``cut``: the share
  with a segment through the wall (``WallMaze.blocked``);
* ``ratio``: planned step over the teacher's real step. With ``--teachers`` (one zoo model per planner), the teacher
  runs one deterministic episode on ``Pilot/WallMaze2D-v0`` from every pair: the real step is the mean distance it
  moves per step in its successful episodes, up to the step that first reaches the goal, and its success per class is
  shown beside. Without, the planner's ``holdout.teacher_step`` stands in (the mean step of its distillation rollouts,
  sampled actions; marked ``rollouts``).

Usage::

    OMP_NUM_THREADS=1 python -m benchmarks.wall_landmarks runs/wall-maze-car/models/seed_*/distill/planner.pt
    # with the teachers' real step
    ... --teachers runs/wall-maze-car/models/seed_*/teacher/sac/Pilot-WallMaze2D-v0_1/Pilot-WallMaze2D-v0.zip

Prints the command, a markdown table (one row per planner and class) and one ``JSON`` line per planner.
"""

from __future__ import annotations

import argparse
import itertools
import json
import shlex
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.base_class import BaseAlgorithm

from benchmarks.landmarks import chained_paths, planned_steps
from sb3_pilot.distill import GoalPlanner, env_goal_space, load_teacher
from sb3_pilot.envs import WallMaze, register_envs

TASK = "Pilot/WallMaze2D-v0"
CLASSES = ("across", "same side", "above")
GRID_BOUND = 0.8


def grid_positions(maze: WallMaze, n: int) -> np.ndarray:
    """
    :param maze: the map
    :param n: grid points per axis
    :return: the points of an n x n grid over ``[-0.8, 0.8]^2`` where starts and goals may lie, shape (m, 2)
    """
    if n < 2:
        raise ValueError(f"the grid needs at least 2 points per axis, got {n}")
    axis = np.linspace(-GRID_BOUND, GRID_BOUND, n)
    points = np.stack(np.meshgrid(axis, axis, indexing="ij"), axis=-1).reshape(-1, 2)
    return points[maze.off_wall(points) & maze.is_free(points)]


def grid_pairs(maze: WallMaze, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """
    :param maze: the map
    :param positions: positions of :func:`grid_positions`
    :return: starts and goals of every ordered pair of distinct positions, shape (p, 2) each, and each pair's class
        (one of :data:`CLASSES`)
    """
    first, second = np.nonzero(~np.eye(len(positions), dtype=bool))
    starts, goals = positions[first], positions[second]
    below = (starts[:, 1] < maze.gap_y) & (goals[:, 1] < maze.gap_y)
    same = np.sign(starts[:, 0]) == np.sign(goals[:, 0])
    classes = np.where(below & ~same, "across", np.where(below, "same side", "above"))
    return starts, goals, classes


def wall_counts(maze: WallMaze, landmarks: np.ndarray) -> dict[str, Any]:
    """
    :param maze: the map
    :param landmarks: landmarks of shape (..., 2)
    :return: how many lie inside the wall (``in_wall``), outside the square (``outside``), of how many (``landmarks``),
        and the largest distance from one of them to the free space (``depth``)
    """
    landmarks = landmarks.reshape(-1, 2)
    outside = ~np.all(np.abs(landmarks) <= 1.0, axis=-1)
    return {
        "landmarks": len(landmarks),
        "in_wall": int((~maze.is_free(landmarks) & ~outside).sum()),
        "outside": int(outside.sum()),
        "depth": float(maze.depth(landmarks).max(initial=0.0)),
    }


def round_the_wall(maze: WallMaze, path: np.ndarray, goal: np.ndarray) -> tuple[bool, bool]:
    """
    :param maze: the map
    :param path: a start below the gap and its chained landmarks, shape (horizon + 1, 2)
    :param goal: a goal below the gap on the other side of the wall
    :return: whether the path reaches below the gap on the goal's side with no landmark in the wall and no segment
        through it before (round the wall's top), and whether any of its segments goes through the wall
    """
    cuts = np.array([maze.blocked(start, end) for start, end in itertools.pairwise(path)])
    landmarks = path[1:]
    arrived = np.flatnonzero(
        (landmarks[:, 1] < maze.gap_y)
        & (np.sign(landmarks[:, 0]) == np.sign(goal[0]))
        & (np.abs(landmarks[:, 0]) > maze.wall_half_width)
    )
    through_gap = len(arrived) > 0 and not cuts[: arrived[0] + 1].any()
    return bool(through_gap), bool(cuts.any())


def measure_planner(
    planner: GoalPlanner, maze: WallMaze, positions: np.ndarray, horizon: int, success_distance: float
) -> dict[str, dict[str, Any]]:
    """
    The raw landmarks' measures over the pairs of ``positions`` (see the module's doc), per class.

    :param planner: the goal planner
    :param maze: the map
    :param positions: positions of :func:`grid_positions`
    :param horizon: landmarks per chained path
    :param success_distance: a landmark this close to the goal reaches it
    :return: ``{class: {"pairs", "one_step", "chained", "planned_step", "reached", and for "across" "through_gap"
        and "through_wall"}}`` (shares in [0, 1])
    """
    starts, goals, classes = grid_pairs(maze, positions)
    one_step = planner.predict(starts, goals, snap=False)
    paths = chained_paths(planner, starts, goals, horizon, snap=False)
    steps, reached = planned_steps(paths, goals, success_distance)
    results: dict[str, dict[str, Any]] = {}
    for name in CLASSES:
        index = np.flatnonzero(classes == name)
        if len(index) == 0:
            continue
        result = {
            "pairs": len(index),
            "one_step": wall_counts(maze, one_step[index]),
            "chained": wall_counts(maze, paths[index, 1:]),
            "one_step_length": float(np.linalg.norm(one_step[index] - starts[index], axis=-1).mean()),
            "planned_step": float(steps[index].mean()),
            "reached": float(reached[index].mean()),
        }
        if name == "across":
            outcomes = np.array([round_the_wall(maze, paths[i], goals[i]) for i in index])
            result |= {"through_gap": float(outcomes[:, 0].mean()), "through_wall": float(outcomes[:, 1].mean())}
        results[name] = result
    return results


def teacher_steps(
    teacher: BaseAlgorithm, maze: WallMaze, positions: np.ndarray, env_kwargs: dict[str, Any] | None = None
) -> dict[str, Any]:
    """
    One deterministic episode of ``teacher`` on :data:`TASK` from every pair of ``positions``.

    :param teacher: a model trained on :data:`TASK` (without ``VecNormalize``)
    :param maze: the map
    :param positions: positions of :func:`grid_positions`
    :param env_kwargs: options of the task (those the teacher trained with)
    :return: ``real_step`` (mean distance moved per step in the successful episodes, up to the step that first reaches
        the goal; NaN if none) and ``success`` per class
    """
    starts, goals, classes = grid_pairs(maze, positions)
    envs = [gym.make(TASK, **(env_kwargs or {})) for _ in starts]
    observations = [
        env.reset(options={"start": start, "goal": goal})[0] for env, start, goal in zip(envs, starts, goals, strict=True)
    ]
    moves: list[list[float]] = [[] for _ in envs]
    success = np.zeros(len(envs), dtype=bool)
    done = np.zeros(len(envs), dtype=bool)
    while not done.all():
        batch = {key: np.stack([obs[key] for obs in observations]) for key in observations[0]}
        actions, _ = teacher.predict(batch, deterministic=True)
        for i in np.flatnonzero(~done):
            before = observations[i]["achieved_goal"]
            observations[i], _, terminated, truncated, info = envs[i].step(actions[i])
            moves[i].append(float(np.linalg.norm(observations[i]["achieved_goal"] - before)))
            success[i] = bool(info["is_success"])
            done[i] = success[i] or terminated or truncated
    real = [move for i in np.flatnonzero(success) for move in moves[i]]
    return {
        "real_step": float(np.mean(real)) if real else float("nan"),
        "success": {name: float(success[classes == name].mean()) for name in CLASSES if (classes == name).any()},
    }


def _row(name: str, label: str, result: dict[str, Any], real_step: float, success: float | None) -> str:
    one, chained = result["one_step"], result["chained"]
    through = f"{result['through_gap']:.2f} / {result['through_wall']:.2f}" if "through_gap" in result else "-"
    teacher = "-" if success is None else f"{success:.2f}"
    return (
        f"| {name} | {label} | {result['pairs']} | {one['in_wall']} / {one['outside']} ({one['depth']:.3f}) "
        f"| {chained['in_wall']} / {chained['outside']} of {chained['landmarks']} ({chained['depth']:.3f}) "
        f"| {result['one_step_length']:.3f} | {result['planned_step']:.3f} | {result['planned_step'] / real_step:.2f} "
        f"| {result['reached']:.2f} | {through} | {teacher} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("planners", nargs="+", help="goal planner files distilled on Pilot/WallMaze2D-v0")
    parser.add_argument("--teachers", nargs="+", default=None, help="the teachers' model files, one per planner")
    parser.add_argument("--grid", type=int, default=7, help="grid points per axis")
    parser.add_argument("--horizon", type=int, default=30, help="landmarks per chained path (the task's episode length)")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    if args.teachers is not None and len(args.teachers) != len(args.planners):
        parser.error(f"--teachers takes one model per planner: {len(args.planners)} planners, {len(args.teachers)} teachers")
    if args.horizon < 1:
        parser.error(f"--horizon must be at least 1, got {args.horizon}")
    missing = [path for path in [*args.planners, *(args.teachers or [])] if not Path(path).is_file()]
    if missing:
        parser.error(f"no such file: {', '.join(missing)}")
    normalized = [path for path in args.teachers or [] if (Path(path).parent / Path(path).stem / "vecnormalize.pkl").is_file()]
    if normalized:
        parser.error(f"teachers trained with VecNormalize are not supported: {', '.join(normalized)}")
    th.set_num_threads(args.threads)
    register_envs()
    env = gym.make(TASK)
    maze, success_distance = env.unwrapped.maze, env.unwrapped.distance_threshold
    planners = [GoalPlanner.load(path) for path in args.planners]
    for path, planner in zip(args.planners, planners, strict=True):
        if planner.source_goal_space != env_goal_space(env):
            parser.error(f"{path} plans in the goal space {planner.source_goal_space!r}, not {TASK}'s {env_goal_space(env)!r}")
    positions = grid_positions(maze, args.grid)
    print(f"command: python -m benchmarks.wall_landmarks {shlex.join(sys.argv[1:])}", flush=True)
    print(
        f"{len(positions)} grid positions, {len(positions) * (len(positions) - 1)} pairs, horizon {args.horizon}", flush=True
    )
    print(
        "| planner | class | pairs | one step: in wall / out (depth) | chained: in wall / out (depth) | one step length "
        "| planned step | ratio | reached | across: gap / cut | teacher success |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|",
        flush=True,
    )
    for index, (path, planner) in enumerate(zip(args.planners, planners, strict=True)):
        results = measure_planner(planner, maze, positions, args.horizon, success_distance)
        record: dict[str, Any] = {"planner": path, "grid": args.grid, "horizon": args.horizon, "classes": results}
        if args.teachers is not None:
            teacher = load_teacher(args.teachers[index], device="cpu")
            record |= {"teacher": args.teachers[index], **teacher_steps(teacher, maze, positions)}
            real_step, source = record["real_step"], "real"
        else:
            real_step, source = planner.metadata["holdout"]["teacher_step"], "rollouts"
            record["rollouts_teacher_step"] = real_step
        for name, result in results.items():
            success = record["success"].get(name) if "success" in record else None
            print(_row(path, name, result, real_step, success), flush=True)
        print(f"  (step of the teacher, {source}: {real_step:.3f})", flush=True)
        print("JSON " + json.dumps(record), flush=True)


if __name__ == "__main__":
    main()
