"""
Are UDPO's landmarks *immediate*? UDPO + HER on a 2D maze, then ``distill_goal_planner``, then the imagined path of
the distilled goal planner from the far start to the far goal, per seed:

* ``success``: UDPO's deterministic success on 20 uniform-goal episodes at each checkpoint, and on 20 far-goal
  episodes at the end;
* ``real step``: mean distance moved per step by the trained policy in its successful uniform-goal episodes, up to
  the step that first reaches the goal (the step length of a successful policy);
* ``teacher step``: at the same states, the mean distance from the state to UDPO's own planned next state (the mean
  of ``h``), and ``teacher error`` the mean distance from that plan to the state actually reached;
* ``planned step``: mean distance between consecutive landmarks of the distilled planner's 40-landmark imagined path
  from the far start (``planner.plan``'s default: each landmark snapped to the nearest of the planner's support
  goals, positions the source really occupied), up to the first landmark within 1.0 of the far goal, and ``ratio``
  = planned step / real step;
* ``in walls``: how many of the 40 chained landmarks lie inside a wall (or outside the map), and ``depth`` the
  largest distance from one of them to the free space (a landmark on a wall's face is 0 deep: a teacher that slides
  along walls gives labels on the face, and a smooth student lands on either side of it);
* ``follow k``: a point that starts at the far start and at every step moves with the maze's own dynamics towards
  the k-th landmark chained from where it is (action ``clip((landmark - position) / 0.5, -1, 1)``) reaches the far
  goal (within 1.0) in at most 100 steps (1 or 0), for k = 1..5;
* ``raw``: the same imagined path and follower with the planner's own landmarks, unsnapped
  (``plan(..., snap=False)``).

Tasks: ``maze2d`` is ``Pilot/Maze2D-v0`` with uniform goals (U-maze, far start (-4, 4), far goal (-4, -4));
``rooms`` is the same kinematic point (0.5 per axis and step, sliding along walls, 50-step episodes) in two 8x12
rooms joined by a 4-unit door in the middle of their shared wall (far start (-8, 4), far goal (8, 4): the straight
line crosses the wall). UDPO uses the ``cpu`` preset's Maze2D settings (hyperparams/cpu/udpo.yml) on both, with
``--udpo-kwargs`` overriding them. Usage::

    OMP_NUM_THREADS=1 python -m benchmarks.landmarks --task maze2d --seeds 0 1 2 --steps 20000
    # distillation variants, e.g. deterministic rollouts; or only the landmarks of saved planners
    ... --distill-kwargs "{'deterministic': True}"
    ... --task maze2d --planners planner_a.pt planner_b.pt

The JSON lines also hold the greedy follower's end positions (``follow_end``) and the teacher's own path from the
far start (``teacher_far_path``).
"""

from __future__ import annotations

import argparse
import ast
import json
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.monitor import Monitor

from sb3_pilot.distill import GoalPlanner, distill_goal_planner
from sb3_pilot.envs import UMAZE_MAP, UMAZE_SCALING, register_envs, umaze_cell_to_xy, umaze_is_free
from sb3_pilot.udpo import UDPO

# hyperparams/cpu/udpo.yml, Pilot/Maze2D-v0 (planner_coef left to UDPO's default unless --udpo-kwargs sets it)
CPU_PRESET: dict[str, Any] = dict(
    gamma=0.99,
    buffer_size=100_000,
    batch_size=128,
    learning_rate=3e-4,
    planner_learning_rate=3e-4,
    inverse_dynamics_learning_rate=1e-4,
    inverse_dynamics_interval=1500,
    replay_buffer_class=HerReplayBuffer,
    replay_buffer_kwargs=dict(goal_selection_strategy="future", n_sampled_goal=4),
)
SUCCESS_DISTANCE = 1.0
HORIZON = 40
FOLLOW_STEPS = 100

# Two rooms and a door: 1 = wall, cells of 4x4 units centred on the origin
ROOMS_MAP = (
    (1, 1, 1, 1, 1, 1, 1),
    (1, 0, 0, 1, 0, 0, 1),
    (1, 0, 0, 0, 0, 0, 1),
    (1, 0, 0, 1, 0, 0, 1),
    (1, 1, 1, 1, 1, 1, 1),
)
CELL = 4.0


class GridMaze:
    """Free-space test and wall sliding of a point in a grid map (cells of ``CELL`` units, centred on the origin)."""

    def __init__(self, grid: tuple[tuple[int, ...], ...]):
        self.grid = np.array(grid)
        rows, cols = self.grid.shape
        self.x_center, self.y_center = cols / 2 * CELL, rows / 2 * CELL
        free = [(r, c) for r in range(rows) for c in range(cols) if self.grid[r, c] == 0]
        self.free_centers = np.array([[(c + 0.5) * CELL - self.x_center, self.y_center - (r + 0.5) * CELL] for r, c in free])

    def cell_xy(self, row: int, col: int) -> np.ndarray:
        return np.array([(col + 0.5) * CELL - self.x_center, self.y_center - (row + 0.5) * CELL])

    def is_free(self, xy: np.ndarray) -> np.ndarray:
        offset = np.abs(np.asarray(xy, dtype=np.float64)[..., None, :] - self.free_centers)
        return np.any(np.all(offset <= CELL / 2, axis=-1), axis=-1)

    def slide(self, position: np.ndarray, delta: float, axis: int) -> np.ndarray:
        moved = position.copy()
        moved[axis] += delta
        if self.is_free(moved):
            return moved
        center = self.x_center if axis == 0 else self.y_center
        lines = (moved[axis] + center) / CELL
        moved[axis] = (np.floor(lines) if delta > 0 else np.ceil(lines)) * CELL - center
        return moved if self.is_free(moved) else position


ROOMS = GridMaze(ROOMS_MAP)


class RoomsEnv(gym.Env):
    """
    Maze2D's kinematic point in :data:`ROOMS_MAP`; uniform goals and starts as Maze2D's ``"uniform"``, the same sparse
    -1/0 reward (goal within ``SUCCESS_DISTANCE``), never terminated.
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(self, step_size: float = 0.5):
        self.step_size = step_size
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        point = gym.spaces.Box(-np.inf, np.inf, shape=(2,), dtype=np.float32)
        self.observation_space = gym.spaces.Dict({"observation": point, "achieved_goal": point, "desired_goal": point})
        self.position, self.goal = np.zeros(2), np.zeros(2)

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        """Vectorised sparse reward, as SB3's ``HerReplayBuffer`` expects: 0 within ``SUCCESS_DISTANCE``, else -1."""
        distance = np.linalg.norm(np.asarray(achieved_goal, np.float64) - np.asarray(desired_goal, np.float64), axis=-1)
        return (distance <= SUCCESS_DISTANCE).astype(np.float32) - 1.0

    def _get_obs(self) -> dict[str, np.ndarray]:
        position = self.position.astype(np.float32)
        return {"observation": position, "achieved_goal": position.copy(), "desired_goal": self.goal.astype(np.float32)}

    def _reward_info(self, obs: dict[str, np.ndarray]) -> tuple[float, dict[str, Any]]:
        reward = float(self.compute_reward(obs["achieved_goal"], obs["desired_goal"], None))
        return reward, {"is_success": reward == 0.0}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        centers, noise = ROOMS.free_centers, CELL / 4
        self.goal = centers[self.np_random.integers(len(centers))] + self.np_random.uniform(-noise, noise, size=2)
        start = self.goal.copy()
        while np.linalg.norm(start - self.goal) <= CELL / 2:
            start = centers[self.np_random.integers(len(centers))]
        self.position = start + self.np_random.uniform(-noise, noise, size=2)
        obs = self._get_obs()
        return obs, self._reward_info(obs)[1]

    def step(self, action: np.ndarray):
        delta = self.step_size * np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        for axis in (0, 1):
            self.position = ROOMS.slide(self.position, delta[axis], axis)
        obs = self._get_obs()
        reward, info = self._reward_info(obs)
        return obs, reward, False, False, info


def wall_depth(points: np.ndarray, free_centers: np.ndarray, cell: float) -> np.ndarray:
    """
    :param points: xy points, shape (n, 2)
    :param free_centers: centres of a map's free square cells
    :param cell: their side
    :return: each point's distance to the nearest free cell (0 in the free space)
    """
    outside = np.maximum(np.abs(points[:, None, :] - free_centers[None]) - cell / 2, 0.0)
    return np.linalg.norm(outside, axis=-1).min(axis=1)


TASKS: dict[str, dict[str, Any]] = {
    "maze2d": dict(
        start=np.array([-4.0, 4.0]),
        goal=np.array([-4.0, -4.0]),
        is_free=umaze_is_free,
        free_centers=np.array(
            [umaze_cell_to_xy((r, c)) for r, row in enumerate(UMAZE_MAP) for c, wall in enumerate(row) if not wall]
        ),
        cell=UMAZE_SCALING,
    ),
    "rooms": dict(
        start=ROOMS.cell_xy(1, 1), goal=ROOMS.cell_xy(1, 5), is_free=ROOMS.is_free, free_centers=ROOMS.free_centers, cell=CELL
    ),
}


def make_env(task: str, far: bool = False) -> gym.Env:
    if task == "maze2d":
        return gym.make("Pilot/Maze2D-v0", goal_distribution="far" if far else "uniform")
    return gym.wrappers.TimeLimit(RoomsEnv(), max_episode_steps=50)


def place(env: gym.Env, start: np.ndarray, goal: np.ndarray) -> dict[str, np.ndarray]:
    """Put the point of a (reset) kinematic maze env at ``start`` with goal ``goal``."""
    inner = env.unwrapped  # Pilot/Maze2D-v0's point or RoomsEnv: both keep ``position`` and ``goal``
    inner.position, inner.goal = np.array(start, dtype=np.float64), np.array(goal, dtype=np.float64)
    return inner._get_obs()


def evaluate(model: UDPO, task: str, n_episodes: int, seed: int, far: bool = False) -> dict[str, float]:
    """Success of deterministic episodes; step lengths of the successful ones (real and planned by UDPO's ``h``)."""
    env = make_env(task, far)
    successes, real_steps, teacher_steps, teacher_errors = [], [], [], []
    for episode in range(n_episodes):
        obs, _ = env.reset(seed=seed + episode)
        if far:
            obs = place(env, TASKS[task]["start"] + env.unwrapped.np_random.uniform(-1, 1, 2), TASKS[task]["goal"])
        done, info, steps = False, {}, []
        reached = False
        while not done:
            planned = model.predict_next_state(obs)[-2:]
            action, _ = model.predict(obs, deterministic=True)
            next_obs, _, terminated, truncated, info = env.step(action)
            if not reached:
                steps.append((obs["achieved_goal"], planned, next_obs["achieved_goal"]))
                reached = bool(info["is_success"])
            obs, done = next_obs, terminated or truncated
        successes.append(float(info["is_success"]))
        if info["is_success"]:
            for achieved, planned, next_achieved in steps:
                real_steps.append(np.linalg.norm(next_achieved - achieved))
                teacher_steps.append(np.linalg.norm(planned - achieved))
                teacher_errors.append(np.linalg.norm(planned - next_achieved))
    nan = float("nan")
    return {
        "success": float(np.mean(successes)),
        "real_step": float(np.mean(real_steps)) if real_steps else nan,
        "teacher_step": float(np.mean(teacher_steps)) if teacher_steps else nan,
        "teacher_error": float(np.mean(teacher_errors)) if teacher_errors else nan,
    }


def chained_paths(
    planner: GoalPlanner, starts: np.ndarray, goals: np.ndarray, horizon: int, snap: bool | None = None
) -> np.ndarray:
    """
    :param planner: the goal planner
    :param starts: start goals, shape (goal_dim,) or (n, goal_dim)
    :param goals: target goals, same shape
    :param horizon: landmarks per path
    :param snap: snap every landmark to the planner's support goals (None: ``planner.plan``'s default)
    :return: each start followed by its ``horizon`` chained landmarks (``planner.plan``, the means), shape
        (horizon + 1, goal_dim) or (n, horizon + 1, goal_dim)
    """
    starts, goals = np.asarray(starts, dtype=np.float32), np.asarray(goals, dtype=np.float32)
    return np.concatenate([starts[..., None, :], planner.plan(starts, goals, horizon=horizon, snap=snap)], axis=-2)


def planned_steps(paths: np.ndarray, goals: np.ndarray, success_distance: float) -> tuple[np.ndarray, np.ndarray]:
    """
    :param paths: paths of :func:`chained_paths`, shape (..., horizon + 1, goal_dim)
    :param goals: their target goals, shape (..., goal_dim)
    :param success_distance: a landmark this close to the goal reaches it
    :return: each path's mean distance between consecutive points up to its first landmark that reaches the goal
        (the whole path if none does), and whether one does, both of shape (...)
    """
    steps = np.linalg.norm(np.diff(paths, axis=-2), axis=-1)
    near = np.linalg.norm(paths[..., 1:, :] - np.asarray(goals)[..., None, :], axis=-1) <= success_distance
    reached = near.any(axis=-1)
    n_steps = np.where(reached, near.argmax(axis=-1) + 1, steps.shape[-1])
    rows = zip(steps.reshape(-1, steps.shape[-1]), n_steps.reshape(-1), strict=True)
    return np.array([row[:count].mean() for row, count in rows]).reshape(n_steps.shape), reached


def imagined_path(planner: GoalPlanner, task: str, snap: bool | None = None) -> dict[str, Any]:
    goal = TASKS[task]["goal"].astype(np.float32)
    path = chained_paths(planner, TASKS[task]["start"], goal, HORIZON, snap)
    planned_step, reached = planned_steps(path, goal, SUCCESS_DISTANCE)
    return {
        "planned_step": float(planned_step),
        "in_walls": int((~TASKS[task]["is_free"](path[1:])).sum()),
        "wall_depth": float(wall_depth(path[1:], TASKS[task]["free_centers"], TASKS[task]["cell"]).max()),
        "path_reaches_goal": bool(reached),
        "path_end": path[-1].round(2).tolist(),
        "path": path.round(2).tolist(),
    }


def follow(planner: GoalPlanner, task: str, k: int, snap: bool | None = None) -> tuple[bool, list[float]]:
    """
    A point that steps greedily towards the k-th chained landmark: whether it reaches the far goal within
    FOLLOW_STEPS, and where it ends.
    """
    env = make_env(task, far=True)
    env.reset(seed=0)
    goal = TASKS[task]["goal"]
    obs = place(env, TASKS[task]["start"], goal)
    for _ in range(FOLLOW_STEPS):
        position = obs["achieved_goal"]
        landmark = planner.plan(position, goal.astype(np.float32), horizon=k, snap=snap)[-1]
        obs, *_ = env.step(np.clip((landmark - position) / 0.5, -1.0, 1.0))
        if np.linalg.norm(obs["achieved_goal"] - goal) <= SUCCESS_DISTANCE:
            return True, obs["achieved_goal"].round(2).tolist()
    return False, obs["achieved_goal"].round(2).tolist()


def teacher_far_path(model: UDPO, task: str) -> list[list[float]]:
    """The teacher's own deterministic path from the far start (no noise) until it reaches the far goal."""
    env = make_env(task, far=True)
    env.reset(seed=0)
    obs = place(env, TASKS[task]["start"], TASKS[task]["goal"])
    path = [obs["achieved_goal"]]
    for _ in range(FOLLOW_STEPS):
        obs, _, _, _, info = env.step(model.predict(obs, deterministic=True)[0])
        path.append(obs["achieved_goal"])
        if info["is_success"]:
            break
    return np.array(path).round(2).tolist()


def landmark_report(planner: GoalPlanner, task: str, snap: bool | None = None) -> dict[str, Any]:
    """
    The imagined path's numbers and the greedy follower's outcome (``follow``) and end (``follow_end``), k = 1..5,
    with the landmarks snapped to the planner's support goals if ``snap`` (None: ``planner.plan``'s default).
    """
    outcomes = [follow(planner, task, k, snap) for k in range(1, 6)]
    return {
        **imagined_path(planner, task, snap),
        "follow": [int(reached) for reached, _ in outcomes],
        "follow_end": [end for _, end in outcomes],
    }


def run(
    task: str, seed: int, steps: int, checkpoints: int, udpo_kwargs: dict[str, Any], distill_kwargs: dict[str, Any]
) -> dict[str, Any]:
    start_time = time.perf_counter()
    model = UDPO("MultiInputPolicy", Monitor(make_env(task)), seed=seed, **{**CPU_PRESET, **udpo_kwargs})
    result: dict[str, Any] = {"task": task, "seed": seed, "udpo_kwargs": {k: str(v) for k, v in udpo_kwargs.items()}}
    successes, train_seconds = [], 0.0
    for _ in range(checkpoints):
        learn_start = time.perf_counter()
        model.learn(steps // checkpoints, reset_num_timesteps=False)
        train_seconds += time.perf_counter() - learn_start
        final = evaluate(model, task, 20, 10_000)
        successes.append(final["success"])
    far = evaluate(model, task, 20, 20_000, far=True)
    planner = distill_goal_planner(model, env=Monitor(make_env(task)), **{"seed": seed, **distill_kwargs})
    path = landmark_report(planner, task)
    result["distill_kwargs"] = {k: str(v) for k, v in distill_kwargs.items()}
    result["labels"] = planner.metadata["labels"]
    result["rollout_success"] = planner.metadata.get("rollout_success")
    result["teacher_far_path"] = teacher_far_path(model, task)
    if planner.has_support:
        result["raw"] = landmark_report(planner, task, snap=False)
    if planner.metadata["labels"] != "planned":  # also the distillation of the plans themselves, for comparison
        result["from_plans"] = landmark_report(distill_goal_planner(model, seed=seed, labels="planned"), task, snap=False)
    result.update(
        success=successes,
        far_success=far["success"],
        real_step=final["real_step"],
        teacher_step=final["teacher_step"],
        teacher_error=final["teacher_error"],
        **path,
        ratio=path["planned_step"] / final["real_step"],
        train_steps_per_s=model.num_timesteps / train_seconds,
        seconds=time.perf_counter() - start_time,
    )
    return result


def _landmarks(report: dict[str, Any], real_step: float | None = None) -> str:
    ratio = "" if real_step is None else f", ratio {report['planned_step'] / real_step:.2f}"
    return (
        f"planned step {report['planned_step']:.2f}{ratio}, in walls {report['in_walls']}/{HORIZON} "
        f"({report['wall_depth']:.2f}), follow {' '.join(map(str, report['follow']))}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--task", choices=sorted(TASKS), default="maze2d")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--checkpoints", type=int, default=4, help="evaluations of UDPO during training")
    parser.add_argument("--udpo-kwargs", default="{}", help="UDPO arguments over the cpu preset, a Python dict literal")
    parser.add_argument("--distill-kwargs", default="{}", help="distill_goal_planner arguments, a Python dict literal")
    parser.add_argument("--planners", nargs="+", default=None, help="only measure these saved goal planners' landmarks")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    th.set_num_threads(args.threads)
    register_envs()
    if args.planners:
        for path in args.planners:
            planner = GoalPlanner.load(path)
            for snap in (None, False) if planner.has_support else (None,):
                report = landmark_report(planner, args.task, snap)
                print(f"{path}{' (raw)' if snap is False else ''}: {_landmarks(report)}", flush=True)
        return
    udpo_kwargs, distill_kwargs = ast.literal_eval(args.udpo_kwargs), ast.literal_eval(args.distill_kwargs)
    print(f"task={args.task} steps={args.steps} udpo_kwargs={udpo_kwargs} distill_kwargs={distill_kwargs}", flush=True)
    print(
        "| seed | success @checkpoints (far) | real step | teacher step / error | planned step | ratio | in walls "
        "(depth) | follow k=1..5 |",
        flush=True,
    )
    for seed in args.seeds:
        r = run(args.task, seed, args.steps, args.checkpoints, udpo_kwargs, distill_kwargs)
        print("JSON " + json.dumps(r), flush=True)
        for key, label in (("raw", "raw, unsnapped"), ("from_plans", "distilled from the plans instead")):
            if key in r:
                print(f"  ({label}: {_landmarks(r[key], r['real_step'])})", flush=True)
        print(
            f"| {seed} | {' / '.join(f'{s:.2f}' for s in r['success'])} ({r['far_success']:.2f}) | {r['real_step']:.2f} "
            f"| {r['teacher_step']:.2f} / {r['teacher_error']:.2f} | {r['planned_step']:.2f} | {r['ratio']:.2f} "
            f"| {r['in_walls']}/{HORIZON} ({r['wall_depth']:.2f}) | {' '.join(map(str, r['follow']))} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
