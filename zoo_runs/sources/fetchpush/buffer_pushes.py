"""
How often the object moved in the episodes of a FetchPush run's replay buffer (the zoo's ``replay_buffer.pkl``,
``--save-replay-buffer``; one env, 50-step episodes): per window of env steps, the share of episodes whose object moved
more than 2 cm from its start, the mean smallest gripper-object distance, and how the gripper moved: the mean
``|a|`` and mean ``a`` of the buffer actions on x, y, z (the actions taken, noise included), and the mean cosine
between the gripper's step and the direction from the gripper to the object (negative: away from it). The buffer
holds raw observations (SB3 stores them before ``VecNormalize``).

    python zoo_runs/sources/fetchpush/buffer_pushes.py /tmp/early/sac/lean_sac/Pilot-FetchPush-v0_1 \
        /tmp/early/udpo/udpo/Pilot-FetchPush-v0_1 --window 5000
"""

import argparse
from pathlib import Path

import numpy as np
from stable_baselines3.common.save_util import load_from_pkl

EPISODE_STEPS = 50


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("folders", nargs="+", help="zoo run folders holding replay_buffer.pkl")
    parser.add_argument("--window", type=int, default=5000, help="env steps per row")
    args = parser.parse_args()
    for folder in args.folders:
        buffer = load_from_pkl(Path(folder) / "replay_buffer.pkl")
        if buffer.n_envs != 1:
            raise ValueError(f"{folder}: {buffer.n_envs} envs; this script reads one env's 50-step episodes")
        steps = buffer.buffer_size if buffer.full else buffer.pos
        episodes = steps // EPISODE_STEPS
        observation = buffer.observations["observation"][: episodes * EPISODE_STEPS, 0]
        start = buffer.observations["achieved_goal"][: episodes * EPISODE_STEPS : EPISODE_STEPS, 0]
        end = buffer.next_observations["achieved_goal"][EPISODE_STEPS - 1 : episodes * EPISODE_STEPS : EPISODE_STEPS, 0]
        moved = np.linalg.norm(end - start, axis=1) > 0.02
        distance = np.linalg.norm(observation[:, 3:6] - observation[:, :3], axis=1).reshape(episodes, EPISODE_STEPS)
        closest = distance.min(axis=1)
        actions = buffer.actions[: episodes * EPISODE_STEPS, 0, :3].reshape(episodes, EPISODE_STEPS, 3)
        step = buffer.next_observations["observation"][: episodes * EPISODE_STEPS, 0, :3] - observation[:, :3]
        to_object = observation[:, 3:6] - observation[:, :3]
        cosine = (step * to_object).sum(axis=1) / (np.linalg.norm(step, axis=1) * np.linalg.norm(to_object, axis=1) + 1e-9)
        cosine = cosine.reshape(episodes, EPISODE_STEPS)
        per_window = args.window // EPISODE_STEPS
        print(f"{folder}: {episodes} episodes, {moved.sum()} moved the object")
        for first in range(0, episodes, per_window):
            rows = slice(first, first + per_window)
            print(
                f"  steps {first * EPISODE_STEPS}-{min(first + per_window, episodes) * EPISODE_STEPS}: "
                f"object moved in {moved[rows].mean():.2f} of episodes, closest gripper-object {closest[rows].mean():.3f} m, "
                f"|a| xyz {np.abs(actions[rows]).mean(axis=(0, 1)).round(2)}, "
                f"a xyz {actions[rows].mean(axis=(0, 1)).round(2)}, "
                f"cos(step, to object) {cosine[rows].mean():+.2f}"
            )


if __name__ == "__main__":
    main()
