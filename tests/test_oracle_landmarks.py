import gymnasium as gym
import numpy as np
import pytest

from benchmarks.oracle_landmarks import OracleBonusWrapper, UMazeOraclePlanner
from sb3_pilot.envs import register_envs
from sb3_pilot.envs.maze import umaze_is_free


def test_oracle_landmarks_go_around_the_inner_wall():
    planner = UMazeOraclePlanner(step=0.7)
    achieved = np.array([[-4.0, 4.0], [-4.0, 4.0], [4.0, 0.0], [-4.0, -4.0], [0.0, 4.0]])
    desired = np.array([[4.0, 4.0], [-4.0, -4.0], [-4.0, -4.0], [-4.0, 4.0], [0.3, 4.0]])
    landmarks = planner.predict(achieved, desired)
    np.testing.assert_allclose(np.linalg.norm(landmarks - achieved, axis=1), [0.7, 0.7, 0.7, 0.7, 0.3], atol=1e-5)
    np.testing.assert_allclose(landmarks[[0, 4]], [[-3.3, 4.0], [0.3, 4.0]], atol=1e-5)  # in sight: straight on
    top, bottom = planner.corners
    for landmark, start, corner in ((1, 0, top), (2, 2, bottom), (3, 3, bottom)):  # out of sight: to a corner
        heading = (landmarks[landmark] - achieved[start]) / 0.7
        np.testing.assert_allclose(heading, (corner - achieved[start]) / np.linalg.norm(corner - achieved[start]), atol=1e-5)
    assert umaze_is_free(landmarks).all()
    _, lengths = planner.shortest_path(achieved, desired)
    around = 2 * np.hypot(6.5, 1.5) + 5.0  # (-4, 4) to (-4, -4) by both corners, 0.5 off the wall
    np.testing.assert_allclose(lengths, [8.0, around, np.hypot(1.5, 2.5) + np.hypot(6.5, 1.5), around, 0.3], atol=1e-6)


def test_oracle_bonus_wrapper_on_the_car():
    register_envs()
    env = OracleBonusWrapper(gym.make("Pilot/Maze2DCar-v0"), similarity="planned_progress")
    obs, _ = env.reset(seed=0)
    previous = obs["achieved_goal"]
    obs, reward, _, _, info = env.step(env.action_space.sample())
    sparse = env.unwrapped.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
    planned = env.planner.predict(previous, obs["desired_goal"]) - previous
    progress = np.dot(obs["achieved_goal"] - previous, planned) / np.dot(planned, planned)
    assert reward == pytest.approx(sparse + np.clip(progress, -1, 1), abs=1e-5)
