"""
Zero-shot Ant-Maze with an open-ground Ant controller: train it, check it, train and distil the Maze2D goal
planner, and evaluate the controller guided by the planner's landmarks on ``Pilot/AntMaze-v0``.

::

    python -m sb3_pilot.experiments.ant_controller train   --seed 0 -f runs/ctrl
    python -m sb3_pilot.experiments.ant_controller check   --model CONTROLLER.zip
    python -m sb3_pilot.experiments.ant_controller planner --seed 0 -f runs/maze --output planner.pt
    python -m sb3_pilot.experiments.ant_controller guided  --model CONTROLLER.zip --planner planner.pt \
        --horizons 1 2 3 4 --switch none 1.0 --seeds 0 1 2 --episodes 10

``train`` and ``planner`` run the RL Zoo (``python -m sb3_pilot.experiments.zoo train ...``, printed before it runs): the
controller's recipe is ``hyperparams/cpu/ant_controller.yml`` (``--conf-file`` for another, e.g.
``cpu/ant_controller_upright.yml``). ``check`` and ``guided`` print tables (Markdown)
and can write them as JSON (``--json``). ``--version v1`` takes the literature's Ant instead of gymnasium's: the
controller trains on ``Pilot/AntLocomotion-v1`` and is guided on ``Pilot/AntMaze-v1``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_pilot.envs import register_envs
from sb3_pilot.envs.locomotion import ant_up_z
from sb3_pilot.envs.maze import WallMarginWrapper, umaze_wall_distance  # noqa: F401 (their former home: old commands)

#: The versions of the two Ant tasks: ``v0`` gymnasium's Ant, ``v1`` the literature's (``sb3_pilot.envs.locomotion``)
VERSIONS = ("v0", "v1")
CONTROLLER_ENV = "Pilot/AntLocomotion-{version}"
MAZE_ENV = "Pilot/AntMaze-{version}"
SOURCE_ENV = "Pilot/Maze2D-v0"
#: The open-ground check: the training task's goals (0.5-3 units away, success within 0.5), one new goal as soon
#: as one is reached, 500-step episodes, from a random position and heading, and no end when flipped.
CHECK_ENV_KWARGS: dict[str, Any] = {
    "max_episode_steps": 500,
    "goal_range": (0.5, 3.0),
    "goal_hold_steps": 0,
    "distance_threshold": 0.5,
    "reward_type": "dense",
    "terminate_when_flipped": False,
}
DEFAULT_RECIPE = "cpu/ant_controller.yml"  # the controller's recipe, in sb3_pilot's hyperparams/ folder
CHECK_GOAL_TIMEOUT = 100  # steps a goal is given before it counts as missed and is replaced
MAP_EXTENT = 6.0
WALL_MARGIN_WRAPPER = "sb3_pilot.envs.maze.WallMarginWrapper"  # the Maze2D source option, as the zoo's env_wrapper


def _python() -> list[str]:
    return [sys.executable, "-m", "sb3_pilot.experiments.zoo", "train"]


def _run(command: list[str]) -> None:
    print("$", shlex.join(command), flush=True)
    start = time.time()
    subprocess.run(command, check=True)
    print(f"wall time {time.time() - start:.0f} s", flush=True)


def load_controller(path: str | Path) -> Any:
    """The SAC controller alone (no replay buffer, HER's included: it would need the env), on the CPU."""
    from stable_baselines3 import SAC

    from sb3_pilot.common.saved_models import without_replay_buffer

    return SAC.load(path, device="cpu", custom_objects=without_replay_buffer())


def train(args: argparse.Namespace) -> None:
    if args.continue_from is not None:
        continue_training(args)
        return
    command = [
        *_python(),
        "--algo",
        "sac",
        "--env",
        CONTROLLER_ENV.format(version=args.version),
        "--conf-file",
        args.conf_file,
        "--seed",
        str(args.seed),
        "--num-threads",
        "1",
        "--save-freq",
        "50000",
        "--eval-freq",  # `check` evaluates the checkpoints; the zoo's evaluations would shift the run's random stream
        "-1",
        "-f",
        args.log_folder,
    ]
    if args.steps is not None:
        command += ["-n", str(args.steps)]
    _run(command)


def recipe(conf_file: str = DEFAULT_RECIPE, version: str = "v0") -> dict[str, Any]:
    """
    :param conf_file: a controller recipe, relative to ``sb3_pilot``'s ``hyperparams/`` folder
    :param version: the Ant
    :return: its ``Pilot/AntLocomotion-<version>`` entry
    """
    import yaml

    from sb3_pilot.experiments.zoo import hyperparams_dir

    return yaml.safe_load((hyperparams_dir() / conf_file).read_text())[CONTROLLER_ENV.format(version=version)]


def continue_training(args: argparse.Namespace) -> None:
    """
    Train a saved controller further, with the recipe's env. The zoo saves no replay buffer here (300k transitions),
    and continuing through the zoo would refill it with ``learning_starts`` random-action steps; this refills it
    with ``--warmup`` steps of the controller's own (stochastic) actions, without updates, then trains on.
    """
    import torch as th
    from stable_baselines3.common.callbacks import CheckpointCallback
    from stable_baselines3.common.env_util import make_vec_env

    th.set_num_threads(1)
    entry = recipe(args.conf_file, args.version)
    output = Path(args.output)
    output.parent.mkdir(parents=True, exist_ok=True)
    env = make_vec_env(
        CONTROLLER_ENV.format(version=args.version),
        n_envs=entry["n_envs"],
        seed=args.seed,
        env_kwargs=entry["env_kwargs"],
        monitor_dir=str(output.parent),
        monitor_kwargs=eval(entry["monitor_kwargs"]),
    )
    from stable_baselines3 import SAC

    model = SAC.load(args.continue_from, env=env, device="cpu")
    start, steps = model.num_timesteps, model.gradient_steps
    print(f"continuing {args.continue_from} from {start} steps: {args.warmup} warm-up steps, then {args.steps}", flush=True)
    model.learning_starts, model.gradient_steps = 0, 0  # the policy's own actions, no update
    model.learn(args.warmup, reset_num_timesteps=False, log_interval=100)
    model.gradient_steps = steps
    checkpoints = CheckpointCallback(max(args.save_freq // entry["n_envs"], 1), str(output.parent), name_prefix="continued")
    wall = time.time()
    model.learn(args.steps, reset_num_timesteps=False, callback=checkpoints, log_interval=20)
    model.save(output)
    print(f"saved {output} at {model.num_timesteps} steps ({time.time() - wall:.0f} s of training)", flush=True)


def open_ground_check(model: Any, episodes: int, seed: int, version: str = "v0") -> dict[str, float]:
    """
    The controller on open ground, from a random position in the map's extent and a random heading, chasing goals
    0.5-3 units away (a new one once within 0.5, or after ``CHECK_GOAL_TIMEOUT`` steps) for 500 steps.

    :param version: the Ant (``Pilot/AntLocomotion-<version>``)

    :return: ``success`` (goals reached / goals set), ``goals_per_episode``, ``steps_per_goal`` (of the reached
        ones), ``flipped`` (fraction of steps with the torso's up axis pointing down), ``speed`` (mean xy
        displacement per step) and ``progress`` (mean decrease of the distance to the goal per step)
    """
    env = gym.make(CONTROLLER_ENV.format(version=version), **CHECK_ENV_KWARGS)
    ant = env.unwrapped
    rng = np.random.default_rng(seed)
    reached, missed, steps_to_goal, flipped, speed, progress = 0, 0, [], [], [], []
    for episode in range(episodes):
        yaw = rng.uniform(-np.pi, np.pi)
        ant.init_qpos[:2] = rng.uniform(-MAP_EXTENT, MAP_EXTENT, size=2)
        ant.init_qpos[3:7] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
        observation, _ = env.reset(seed=seed * 10_000 + episode)
        since_goal, done = 0, False
        while not done:
            position, distance = ant.data.qpos[:2].copy(), ant.distance_to_goal()
            action, _ = model.predict(observation, deterministic=True)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            since_goal += 1
            speed.append(float(np.linalg.norm(ant.data.qpos[:2] - position)))
            flipped.append(ant_up_z(ant.data.qpos) < 0)
            if info["is_success"]:
                reached += 1
                steps_to_goal.append(since_goal)
                since_goal = 0
            else:
                progress.append(distance - ant.distance_to_goal())
                if since_goal >= CHECK_GOAL_TIMEOUT:
                    missed += 1
                    since_goal = 0
                    ant.goal = ant._sample_goal(ant.data.qpos[:2])
                    observation = {**observation, "desired_goal": ant.goal.astype(np.float32)}
    env.close()
    return {
        "success": reached / max(reached + missed, 1),
        "goals_per_episode": reached / episodes,
        "steps_per_goal": float(np.mean(steps_to_goal)) if steps_to_goal else float("nan"),
        "flipped": float(np.mean(flipped)),
        "speed": float(np.mean(speed)),
        "progress": float(np.mean(progress)) if progress else float("nan"),
    }


def check(args: argparse.Namespace) -> None:
    model = load_controller(args.model)
    rows = {}
    for seed in args.seeds:
        rows[seed] = open_ground_check(model, args.episodes, seed, args.version)
    keys = list(next(iter(rows.values())))
    print(f"\nOpen-ground check of {args.model}: {args.episodes} episodes of 500 steps per seed")
    print("| seed | " + " | ".join(keys) + " |")
    print("|---" * (len(keys) + 1) + "|")
    for seed, row in rows.items():
        print(f"| {seed} | " + " | ".join(f"{row[key]:.3f}" for key in keys) + " |")
    mean = {key: float(np.mean([row[key] for row in rows.values()])) for key in keys}
    print("| mean | " + " | ".join(f"{mean[key]:.3f}" for key in keys) + " |")
    if args.json:
        Path(args.json).write_text(json.dumps({"model": str(args.model), "per_seed": rows, "mean": mean}, indent=2))


def planner(args: argparse.Namespace) -> None:
    from stable_baselines3.common.vec_env import DummyVecEnv

    from sb3_pilot import UDPO, distill_goal_planner
    from sb3_pilot.experiments.zoo_run import find_zoo_run, load_zoo_model

    try:
        model_path = find_zoo_run(args.log_folder, "udpo", SOURCE_ENV)  # the latest run
    except FileNotFoundError:  # none, or the latest has no model (interrupted)
        model_path = None
    if model_path is None or args.retrain:
        _run(
            [
                *_python(),
                "--algo",
                "udpo",
                "--env",
                SOURCE_ENV,
                "--conf-file",
                "cpu/udpo.yml",
                "--env-kwargs",
                "goal_distribution:'uniform'",
                "--save-replay-buffer",
                *(
                    [
                        "--hyperparams",
                        f"env_wrapper:{{'{WALL_MARGIN_WRAPPER}': {{'margin': {args.wall_margin}}}}}",
                    ]
                    if args.wall_margin
                    else []
                ),
                "-n",
                str(args.steps),
                "--seed",
                str(args.seed),
                "--num-threads",
                "1",
                "-f",
                args.log_folder,
            ]
        )
        model_path = find_zoo_run(args.log_folder, "udpo", SOURCE_ENV)
    print(f"distilling {model_path}")
    # the env of the teacher's distillation rollouts: the goals it was trained on
    teacher, _ = load_zoo_model(model_path, env=DummyVecEnv([lambda: gym.make(SOURCE_ENV, goal_distribution="uniform")]))
    assert isinstance(teacher, UDPO)
    teacher.load_replay_buffer(model_path.parent / "replay_buffer.pkl")
    goal_planner = distill_goal_planner(
        teacher, source_task=SOURCE_ENV, seed=args.seed, n_samples=50_000, gradient_steps=5_000
    )
    goal_planner.save(args.output)
    print(f"saved {args.output}; held-out: {goal_planner.metadata['holdout']}")


def guided_episodes(
    model: Any,
    planner: Any,
    horizon: int | None,
    switch_distance: float | None,
    seed: int,
    episodes: int,
    snap: bool = False,
    version: str = "v0",
) -> dict[str, Any]:
    """
    The controller on ``Pilot/AntMaze-<version>`` (far goal), guided by ``LandmarkGuidance(planner, horizon,
    switch_distance, snap)`` or, with ``horizon=None``, shown the real goal directly. Episode ``i`` is reset with seed
    ``10_000 * seed + i``, as the challenges' ``ControllerEvaluation`` stage does.

    :return: ``success`` (goal within 1.0 at the last step, the task's success), ``reached`` (at any step),
        ``flipped`` (fraction of steps), ``final_distance`` (to the real goal), ``speed`` (mean xy move per step)
    """
    from sb3_pilot import LandmarkGuidance

    env = gym.make(MAZE_ENV.format(version=version))
    if horizon is not None:
        env = LandmarkGuidance(env, planner, horizon=horizon, switch_distance=switch_distance, snap=snap)
    maze = env.unwrapped
    success, reached, flipped, final_distance, speed = [], [], [], [], []
    for episode in range(episodes):
        observation, _ = env.reset(seed=10_000 * seed + episode)
        done, ever, info, steps_flipped, path = False, False, {}, 0, 0.0
        steps = 0
        while not done:
            position = maze.data.qpos[:2].copy()
            action, _ = model.predict(observation, deterministic=True)
            observation, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            ever = ever or info["is_success"]
            steps_flipped += ant_up_z(maze.data.qpos) < 0
            path += float(np.linalg.norm(maze.data.qpos[:2] - position))
            steps += 1
        success.append(float(info["is_success"]))
        reached.append(float(ever))
        flipped.append(steps_flipped / steps)
        final_distance.append(float(np.linalg.norm(maze.data.qpos[:2] - maze.goal)))
        speed.append(path / steps)
    env.close()
    return {
        "success": float(np.mean(success)),
        "reached": float(np.mean(reached)),
        "flipped": float(np.mean(flipped)),
        "final_distance": float(np.mean(final_distance)),
        "speed": float(np.mean(speed)),
        "successes": success,
    }


def _switch(value: str) -> float | None:
    return None if value.lower() == "none" else float(value)


def guided(args: argparse.Namespace) -> None:
    from sb3_pilot import GoalPlanner

    model = load_controller(args.model)
    goal_planner = GoalPlanner.load(args.planner)
    configs: list[tuple[int | None, float | None]] = [(k, s) for k in args.horizons for s in args.switch]
    if args.unguided:
        configs.append((None, None))
    results = []
    for horizon, switch_distance in configs:
        start = time.time()
        per_seed = [
            guided_episodes(model, goal_planner, horizon, switch_distance, seed, args.episodes, args.snap, args.version)
            for seed in args.seeds
        ]
        row = {
            "horizon": horizon,
            "switch_distance": switch_distance,
            "per_seed_success": [result["success"] for result in per_seed],
            **{
                key: float(np.mean([result[key] for result in per_seed]))
                for key in ("success", "reached", "flipped", "final_distance", "speed")
            },
        }
        results.append(row)
        label = "unguided (real goal)" if horizon is None else f"k={horizon}, switch={switch_distance}"
        print(f"{label}: {row} ({time.time() - start:.0f} s)", flush=True)
    maze = MAZE_ENV.format(version=args.version)
    print(f"\nGuided zero-shot {maze} (far goal), seeds {args.seeds} x {args.episodes} episodes, deterministic")
    print("| guidance | k | switch | success (per seed) | success | reached | flipped | final dist | speed |")
    print("|---|---|---|---|---|---|---|---|---|")
    for row in results:
        guidance = "none (real goal)" if row["horizon"] is None else "landmarks"
        per_seed = " ".join(f"{value:.1f}" for value in row["per_seed_success"])
        switch = (
            "-" if row["horizon"] is None else ("landmark dist" if row["switch_distance"] is None else row["switch_distance"])
        )
        print(
            f"| {guidance} | {row['horizon'] or '-'} | {switch} | {per_seed} | {row['success']:.2f} | {row['reached']:.2f} | "
            f"{row['flipped']:.3f} | {row['final_distance']:.2f} | {row['speed']:.3f} |"
        )
    if args.json:
        meta = {"model": str(args.model), "planner": str(args.planner), "seeds": args.seeds, "episodes": args.episodes}
        meta["snap"], meta["version"] = args.snap, args.version
        Path(args.json).write_text(json.dumps({**meta, "results": results}, indent=2))


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command", required=True)
    p_train = commands.add_parser("train", help="train the controller with the zoo (hyperparams/cpu/ant_controller.yml)")
    p_train.add_argument("--version", choices=VERSIONS, default="v0", help="the Ant: v0 gymnasium's, v1 the literature's")
    p_train.add_argument("--seed", type=int, default=0)
    p_train.add_argument("--steps", type=int, default=None, help="override n_timesteps")
    p_train.add_argument("--conf-file", default=DEFAULT_RECIPE, help="the recipe, in sb3_pilot's hyperparams/ folder")
    p_train.add_argument("-f", "--log-folder", default="runs/ctrl")
    p_train.add_argument("--continue-from", default=None, help="a saved controller to train further (not with the zoo)")
    p_train.add_argument("--warmup", type=int, default=20_000, help="steps refilling the buffer before updates")
    p_train.add_argument("--output", default="runs/ctrl_continued/controller.zip", help="with --continue-from")
    p_train.add_argument("--save-freq", type=int, default=50_000, help="checkpoint interval in steps, with --continue-from")
    p_train.set_defaults(func=train)
    p_check = commands.add_parser("check", help="open-ground check of a controller")
    p_check.add_argument("--version", choices=VERSIONS, default="v0", help="the Ant: v0 gymnasium's, v1 the literature's")
    p_check.add_argument("--model", required=True)
    p_check.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p_check.add_argument("--episodes", type=int, default=5)
    p_check.add_argument("--json", default=None)
    p_check.set_defaults(func=check)
    p_planner = commands.add_parser("planner", help="train UDPO on Maze2D (zoo) and distil its goal planner")
    p_planner.add_argument("--seed", type=int, default=0)
    p_planner.add_argument("--steps", type=int, default=20_000)
    p_planner.add_argument("-f", "--log-folder", default="runs/maze")
    p_planner.add_argument("--output", default="planner.pt")
    p_planner.add_argument("--retrain", action="store_true", help="train even if the log folder holds a run")
    p_planner.add_argument("--wall-margin", type=float, default=0.0, help="WallMarginWrapper's margin (0: plain Maze2D)")
    p_planner.set_defaults(func=planner)
    p_guided = commands.add_parser("guided", help="evaluate the guided controller on Pilot/AntMaze-v0")
    p_guided.add_argument("--version", choices=VERSIONS, default="v0", help="the Ant: v0 gymnasium's, v1 the literature's")
    p_guided.add_argument("--model", required=True)
    p_guided.add_argument("--planner", required=True)
    p_guided.add_argument("--horizons", type=int, nargs="+", default=[1, 2, 3, 4])
    p_guided.add_argument(
        "--switch", type=_switch, nargs="+", default=[None], help="switch distances ('none': the landmark's)"
    )
    p_guided.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p_guided.add_argument("--episodes", type=int, default=10)
    p_guided.add_argument("--snap", action="store_true", help="snap the landmarks to the planner's support goals")
    p_guided.add_argument("--unguided", action=argparse.BooleanOptionalAction, default=True, help="add the real-goal row")
    p_guided.add_argument("--json", default=None)
    p_guided.set_defaults(func=guided)
    args = parser.parse_args(argv)
    register_envs()
    args.func(args)


if __name__ == "__main__":
    main()
