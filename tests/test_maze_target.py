"""Pilot/Maze2DCar-v0, the car-like target of the maze-car challenge: its dynamics, goals and planner transfer."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from sb3_pilot import GoalPlanner, PilotBonusWrapper
from sb3_pilot.envs import register_envs, umaze_is_free
from sb3_pilot.envs.car import Maze2DCarEnv

register_envs()
CAR = "Pilot/Maze2DCar-v0"


def test_gymnasium_check_env_and_spaces() -> None:
    env = gym.make(CAR)
    check_env(env.unwrapped, skip_render_check=True)
    assert env.spec.max_episode_steps == 50
    assert env.observation_space["observation"].shape == (4,) and env.observation_space["desired_goal"].shape == (2,)
    obs, _ = env.reset(seed=0)
    x, y, cos, sin = obs["observation"]
    np.testing.assert_allclose([x, y], obs["achieved_goal"])
    assert cos**2 + sin**2 == pytest.approx(1.0, abs=1e-6)


def test_turn_then_drive_along_the_heading() -> None:
    env = Maze2DCarEnv()
    env.reset(seed=0)
    env.position, env.heading = np.array([0.0, 4.0]), 0.0  # the top corridor's middle, facing +x
    obs, reward, *_ = env.step(np.array([1.0, 0.0]))
    np.testing.assert_allclose(obs["observation"], [0.5, 4.0, 1.0, 0.0], atol=1e-6)
    obs, *_ = env.step(np.array([0.0, 1.0]))  # a turn alone does not move
    np.testing.assert_allclose(obs["observation"], [0.5, 4.0, np.cos(np.pi / 4), np.sin(np.pi / 4)], atol=1e-6)
    obs, *_ = env.step(np.array([-1.0, 0.0]))  # backwards along the heading
    np.testing.assert_allclose(obs["achieved_goal"], [0.5 - 0.5 * np.cos(np.pi / 4), 4.0 - 0.5 * np.sin(np.pi / 4)], atol=1e-6)
    assert reward == -1.0 and env.compute_reward(obs["achieved_goal"], obs["achieved_goal"], {}) == 0.0


def test_walls_stop_the_car_and_it_stays_free() -> None:
    env = Maze2DCarEnv()
    env.reset(seed=0)
    env.position, env.heading = np.array([-4.0, 2.2]), -np.pi / 2  # just above the inner wall (top face y = 2)
    obs, *_ = env.step(np.array([1.0, 0.0]))
    np.testing.assert_allclose(obs["achieved_goal"], [-4.0, 2.0], atol=1e-6)  # stops at the wall's face
    env = gym.make(CAR)
    env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(300):
        obs, _, _, truncated, _ = env.step(rng.uniform(-1, 1, size=2))
        assert umaze_is_free(obs["achieved_goal"])
        if truncated:
            env.reset()


def test_goals_are_maze2ds() -> None:
    """Same starts and goals as Pilot/Maze2D-v0 for the same seed and goal distribution."""
    car, point = gym.make(CAR, goal_distribution="far"), gym.make("Pilot/Maze2D-v0", goal_distribution="far")
    for seed in range(3):
        car_obs, _ = car.reset(seed=seed)
        point_obs, _ = point.reset(seed=seed)
        np.testing.assert_array_equal(car_obs["desired_goal"], point_obs["desired_goal"])
        np.testing.assert_array_equal(car_obs["achieved_goal"], point_obs["achieved_goal"])


def test_a_maze2d_planner_guides_the_car(tmp_path) -> None:
    """A planner distilled on Maze2D is accepted (shared goal space), one distilled elsewhere is refused."""
    path = tmp_path / "maze2d.pt"
    GoalPlanner(2, net_arch=[8], metadata={"source_task": "Pilot/Maze2D-v0"}).save(path)
    env = PilotBonusWrapper(gym.make(CAR), path)
    env.reset(seed=0)
    _, reward, *_ = env.step(env.action_space.sample())
    assert -2.0 <= reward <= 1.0
    GoalPlanner(2, net_arch=[8], metadata={"source_task": "Pilot/PointLocomotion-v0"}).save(path)
    with pytest.raises(ValueError, match="goal space"):
        PilotBonusWrapper(gym.make(CAR), path)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"goal_distribution": "near"}, "goal_distribution"),
        ({"max_speed": 0.0}, "max_speed"),
        ({"max_speed": 4.0}, "max_speed"),
        ({"max_turn": -0.1}, "max_turn"),
        ({"max_turn": 4.0}, "max_turn"),
        ({"render_mode": "human"}, "render_mode"),
    ],
)
def test_bad_arguments(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        gym.make(CAR, **kwargs)
