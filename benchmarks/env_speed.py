"""
Random-action steps per second of every ``Pilot/`` task beside the Gymnasium(-Robotics) task it is built on.

Usage (image tasks need a renderer: ``MUJOCO_GL=osmesa`` on a headless machine)::

    MUJOCO_GL=osmesa python -m benchmarks.env_speed [--steps 2000] [--image-steps 500]

Both sides are made with ``gym.make`` (same wrapper stack) and reset when an episode ends; the overhead
is the ratio of the time per step of the ``Pilot/`` task to that of its reference (below 1: faster).
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym

from sb3_pilot.envs import PILOT_ENV_IDS, register_envs

IMAGE = {"render_mode": "rgb_array", "width": 64, "height": 64}
ANT = {"include_cfrc_ext_in_observation": False}
# Pilot id: (reference id, its kwargs, whether the Pilot task wraps it or is only its nearest relative)
REFERENCES: dict[str, tuple[str, dict[str, Any], bool]] = {
    "Pilot/FetchReach-v0": ("FetchReach-v4", {}, True),
    "Pilot/FetchPush-v0": ("FetchPush-v4", {}, True),
    "Pilot/FetchReachHighDim-v0": ("FetchReach-v4", {}, True),
    "Pilot/FetchPushHighDim-v0": ("FetchPush-v4", {}, True),
    "Pilot/FetchReachImage-v0": ("FetchReach-v4", IMAGE, True),
    "Pilot/Reacher-v0": ("Reacher-v5", {}, False),
    "Pilot/ReacherImage-v0": ("Reacher-v5", IMAGE, False),
    "Pilot/PointLocomotion-v0": ("PointMaze_Open-v3", {}, False),
    "Pilot/AntLocomotion-v0": ("Ant-v5", ANT, True),
    "Pilot/Maze2D-v0": ("PointMaze_UMaze-v3", {}, False),
    "Pilot/AntMaze-v0": ("AntMaze_UMaze-v5", ANT, True),
}


def steps_per_second(env_id: str, n_steps: int, **kwargs: Any) -> float:
    """
    :param env_id: a registered environment id
    :param n_steps: number of random-action steps to time
    :param kwargs: keyword arguments of ``gym.make``
    :return: steps per second, rendering every step when the environment renders ``rgb_array`` frames
    """
    env = gym.make(env_id, **kwargs)
    render = kwargs.get("render_mode") == "rgb_array"
    env.reset(seed=0)
    env.action_space.seed(0)
    start = time.perf_counter()
    for _ in range(n_steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if render:
            env.render()
        if terminated or truncated:
            env.reset()
    elapsed = time.perf_counter() - start
    env.close()
    return n_steps / elapsed


def main(argv: list[str] | None = None) -> None:
    """
    Print the table, in markdown.

    :param argv: command-line arguments (default: ``sys.argv``)
    """
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=2000, help="steps timed per vector task")
    parser.add_argument("--image-steps", type=int, default=500, help="steps timed per image task")
    parser.add_argument("--ids", nargs="+", default=list(PILOT_ENV_IDS), choices=PILOT_ENV_IDS, metavar="ID")
    args = parser.parse_args(argv)

    import gymnasium_robotics

    gym.register_envs(gymnasium_robotics)
    register_envs()
    print("| task | steps/s | built on | steps/s | overhead (time/step ratio) |")
    print("|---|---:|---|---:|---:|")
    for env_id in args.ids:
        reference, reference_kwargs, wraps = REFERENCES[env_id]
        n_steps = args.image_steps if "Image" in env_id else args.steps
        ours = steps_per_second(env_id, n_steps)
        theirs = steps_per_second(reference, n_steps, **reference_kwargs)
        label = reference + (", rendered 64x64" if reference_kwargs.get("render_mode") else "")
        label = f"`{label}`" + ("" if wraps else " (nearest relative)")
        print(f"| `{env_id}` | {ours:,.0f} | {label} | {theirs:,.0f} | {theirs / ours:.2f} |", flush=True)


if __name__ == "__main__":
    main()
