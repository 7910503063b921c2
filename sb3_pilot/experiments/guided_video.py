"""
A GIF of the guided Ant in Ant-Maze: the shipped open-ground controller, zero-shot, following the landmarks of the
shipped Maze2D goal planner round the U's wall (``--reuse-shipped``'s models, horizon and switch rule), on the
literature's Ant (``Pilot/AntMaze-v1``, the default) or on gymnasium's (``--ant v0``).

    python -m sb3_pilot.experiments.guided_video --output docs/_static/antmaze_v1_guided.gif
    python -m sb3_pilot.experiments.guided_video --ant v0 --output docs/_static/antmaze_guided.gif

The episode is the first that succeeds among the ``zero-shot-ant-maze(-v1)-shipped`` challenge's evaluation episodes,
taken in their order (seed ``s``, episode ``i`` reset with seed ``10_000 s + i``); the command prints which one and
the outcome of those before it. The episodes are played without rendering to find it, then that one is played again,
rendered (top-down, fixed camera): the landmark the controller is shown is the green sphere, the real goal the red
one, the Ant's path so far the small blue dots.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import torch as th

from sb3_pilot.distill import GoalPlanner
from sb3_pilot.envs import register_envs
from sb3_pilot.experiments.challenges.controller import ControllerEvaluation
from sb3_pilot.experiments.challenges.definitions import REUSE_SHIPPED
from sb3_pilot.experiments.challenges.stages import Shipped, ShippedFileMissing, shipped_file
from sb3_pilot.experiments.zoo_run import load_zoo_model
from sb3_pilot.transfer import LandmarkGuidance, horizon_for_lead

#: The challenges whose shipped models, horizon and switch rule the video shows, by the version of the Ant's tasks.
CHALLENGES = {"v0": REUSE_SHIPPED["zero-shot-ant-maze"], "v1": REUSE_SHIPPED["zero-shot-ant-maze-v1"]}
LANDMARK_RGBA = np.array([0.1, 0.85, 0.1, 1.0])
PATH_RGBA = np.array([0.15, 0.35, 1.0, 1.0])
#: Top-down view of the whole U-maze (5 x 5 cells of 4 units, centred on the origin).
CAMERA = {"lookat": (0.0, 0.0, 0.0), "distance": 17.0, "elevation": -90.0, "azimuth": 90.0}


def shipped_guidance(ant: str) -> tuple[Path, Path, ControllerEvaluation]:
    """
    The shipped controller's and planner's paths and the challenge's guidance stage (horizon, switch rule).

    :param ant: the version of the Ant's tasks, a key of :data:`CHALLENGES`
    """
    challenge = CHALLENGES[ant]
    shipped = {stage.name: stage.path for stage in challenge.stages if isinstance(stage, Shipped)}
    (guidance,) = (stage for stage in challenge.stages if isinstance(stage, ControllerEvaluation) and stage.planner)
    assert guidance.planner is not None
    return shipped[guidance.controller], shipped[guidance.planner], guidance


def guided_env(
    planner: GoalPlanner, guidance: ControllerEvaluation, max_steps: int | None, render_size: int | None
) -> LandmarkGuidance:
    """``Pilot/AntMaze-v0`` (``-v1``) guided as the challenge's stage does, rendered top-down if ``render_size`` is given."""
    task = gym.make(
        guidance.env_id,
        **({"max_episode_steps": max_steps} if max_steps else {}),
        **({"render_mode": "rgb_array"} if render_size else {}),
    )
    if render_size:
        renderer = task.unwrapped.ant_env.mujoco_renderer
        renderer.width = renderer.height = render_size
        renderer.camera_id = -1  # a free camera, set below (the default one tracks the Ant)
        camera = renderer._get_viewer("rgb_array").cam
        camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        camera.lookat[:] = CAMERA["lookat"]
        camera.distance, camera.elevation, camera.azimuth = CAMERA["distance"], CAMERA["elevation"], CAMERA["azimuth"]
    horizon = guidance.horizon
    if guidance.lead is not None:  # as the stage chooses it: on the task's own start and goal pairs
        horizon = horizon_for_lead(task, planner, guidance.lead, max_horizon=guidance.max_horizon)
    return LandmarkGuidance(task, planner, horizon=horizon, switch_distance=guidance.switch_distance)


def frame(env: LandmarkGuidance, path: list[np.ndarray]) -> np.ndarray:
    """The rendered maze with the current landmark and the path so far drawn in."""
    viewer = env.unwrapped.ant_env.mujoco_renderer._get_viewer("rgb_array")
    sphere = mujoco.mjtGeom.mjGEOM_SPHERE
    landmark = env.episode_landmarks[-1]
    viewer.add_marker(pos=np.array([*landmark, 0.6]), size=np.full(3, 0.6), rgba=LANDMARK_RGBA, type=sphere, label="")
    for position in path:
        viewer.add_marker(pos=np.array([*position, 0.3]), size=np.full(3, 0.15), rgba=PATH_RGBA, type=sphere, label="")
    return env.render()


def play(model: Any, env: LandmarkGuidance, reset_seed: int, stride: int | None = None) -> tuple[bool, int, list[np.ndarray]]:
    """
    One deterministic episode (as the challenge's ``play_episodes``).

    :param stride: render every ``stride``-th step (None: no frames)
    :return: success, number of steps, frames
    """
    observation, _ = env.reset(seed=reset_seed)
    done, info, steps, frames, path = False, {}, 0, [], []
    while not done:
        if stride is not None and steps % stride == 0:
            path.append(env.episode_achieved_goals[-1])
            frames.append(frame(env, path))
        action, _ = model.predict(observation, deterministic=True)
        observation, _, terminated, truncated, info = env.step(action)
        done, steps = terminated or truncated, steps + 1
    if stride is not None:
        path.append(env.episode_achieved_goals[-1])
        frames.extend([frame(env, path)] * 5)  # hold the last frame
    return bool(info["is_success"]), steps, frames


def save_gif(frames: list[np.ndarray], output: Path, fps: int) -> None:
    """Write the frames as a looping GIF (one palette for all, so the file stays small)."""
    from PIL import Image

    images = [Image.fromarray(array) for array in frames]
    # the palette of the first, middle and last frames side by side: the maze, the markers and the whole path
    sample = Image.fromarray(np.concatenate([frames[0], frames[len(frames) // 2], frames[-1]], axis=1))
    palette = sample.quantize(colors=128, method=Image.Quantize.MEDIANCUT)
    quantized = [image.quantize(palette=palette, dither=Image.Dither.NONE) for image in images]
    output.parent.mkdir(parents=True, exist_ok=True)
    quantized[0].save(output, save_all=True, append_images=quantized[1:], duration=round(1000 / fps), loop=0, optimize=True)


def main(argv: list[str] | None = None) -> None:
    """Find the first successful evaluation episode of the shipped guided Ant and write it as a GIF."""
    parser = argparse.ArgumentParser(prog="python -m sb3_pilot.experiments.guided_video", description=__doc__)
    parser.add_argument(
        "--ant", choices=list(CHALLENGES), default="v1", help="v1: the literature's Ant (Pilot/AntMaze-v1); v0: gymnasium's"
    )
    parser.add_argument("--output", type=Path, default=Path("docs/_static/antmaze_v1_guided.gif"))
    parser.add_argument("--seeds", type=int, default=3, help="evaluation seeds whose episodes are searched (0 .. N-1)")
    parser.add_argument("--episodes", type=int, default=10, help="episodes per seed (the challenge's cpu budget: 10)")
    parser.add_argument("--size", type=int, default=224, help="frame width and height in pixels")
    parser.add_argument("--stride", type=int, default=5, help="one frame every STRIDE env steps")
    parser.add_argument("--fps", type=int, default=20)
    parser.add_argument("--max-steps", type=int, default=None, help="shorter episodes (a quick check of the command)")
    parser.add_argument("--any", action="store_true", help="draw the first episode whether or not it succeeds")
    args = parser.parse_args(argv)
    controller_path, planner_path, guidance = shipped_guidance(args.ant)
    try:
        for path in (controller_path, planner_path):
            shipped_file(path)
    except ShippedFileMissing as error:
        parser.error(str(error))
    th.set_num_threads(1)
    register_envs()
    model, vec_normalize = load_zoo_model(controller_path, algo=guidance.controller_algo)
    assert vec_normalize is None, "the shipped controller reads raw observations"
    planner = GoalPlanner.load(planner_path)
    search = guided_env(planner, guidance, args.max_steps, None)
    print(f"controller {controller_path.name}, planner {planner_path.name}, k={search.horizon}", flush=True)
    tried = []
    for seed in range(args.seeds):
        for episode in range(args.episodes):
            reset_seed = 10_000 * seed + episode
            success, steps, _ = play(model, search, reset_seed)
            tried.append(success)
            print(f"seed {seed} episode {episode} (reset seed {reset_seed}): success {success}, {steps} steps", flush=True)
            if success or args.any:
                break
        if tried[-1] or args.any:
            break
    else:
        raise SystemExit(f"No successful episode among {len(tried)}: nothing drawn.")
    search.close()

    env = guided_env(planner, guidance, args.max_steps, args.size)
    again, steps, frames = play(model, env, reset_seed, stride=args.stride)
    env.close()
    if again != tried[-1]:
        raise RuntimeError(f"The rendered episode (reset seed {reset_seed}) did not replay the searched one.")
    save_gif(frames, args.output, args.fps)
    print(
        f"Saved {args.output}: reset seed {reset_seed} (success {again}; {len(tried) - 1} episode(s) before it "
        f"failed), {steps} steps, {len(frames)} frames of {args.size}x{args.size}, {args.output.stat().st_size / 1e3:.0f} kB"
    )


if __name__ == "__main__":
    main()
