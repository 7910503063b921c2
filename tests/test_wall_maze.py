"""The walled maze's registered tasks: the point (Pilot/WallMaze2D-v0) and the car (Pilot/WallMaze2DCar-v0)."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from maze_envs import WALL_GOAL, WALL_START, WallMazeEnv

from sb3_pilot import GoalPlanner, LandmarkGuidance, PilotBonusWrapper
from sb3_pilot.distill import env_goal_space
from sb3_pilot.envs import register_envs
from sb3_pilot.envs.wall_maze import WALL_MAZE_GOAL_SPACE, WallMaze, WallMaze2DCarEnv

register_envs()
POINT, CAR = "Pilot/WallMaze2D-v0", "Pilot/WallMaze2DCar-v0"


@pytest.mark.parametrize("env_id", [POINT, CAR])
def test_registered_with_one_goal_space(env_id: str) -> None:
    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    assert env.spec.max_episode_steps == 30 and env.unwrapped.distance_threshold == 0.1
    assert env_goal_space(env) == WALL_MAZE_GOAL_SPACE
    obs, _ = env.reset(seed=0, options={"start": WALL_START, "goal": WALL_GOAL})
    np.testing.assert_array_equal(obs["achieved_goal"], WALL_START)
    np.testing.assert_array_equal(obs["desired_goal"], WALL_GOAL)
    np.testing.assert_array_equal(obs["observation"][:2], WALL_START)


def test_the_tests_maze_is_the_registered_point() -> None:
    """The tests' WallMazeEnv (no gym.make, its own truncation) steps as Pilot/WallMaze2D-v0 does."""
    registered, ours = gym.make(POINT), WallMazeEnv()
    rng = np.random.default_rng(0)
    for seed in range(3):
        first, _ = registered.reset(seed=seed)
        second, _ = ours.reset(seed=seed)
        for step in range(30):
            action = rng.uniform(-1, 1, size=2).astype(np.float32)
            first, reward, _, truncated, _ = registered.step(action)
            second, our_reward, _, our_truncated, _ = ours.step(action)
            for key in first:
                np.testing.assert_array_equal(first[key], second[key])
            assert reward == our_reward and truncated == our_truncated == (step == 29)


def test_the_wall_blocks_and_the_gap_lets_through() -> None:
    maze, sliding = WallMaze(), WallMaze(slide=True)
    start = np.array([-0.1, -0.5])
    np.testing.assert_array_equal(maze.move(start, np.array([0.2, 0.1])), start)  # across the wall: no move
    np.testing.assert_allclose(sliding.move(start, np.array([0.2, 0.1])), [-0.1, -0.4])  # its part along the wall
    np.testing.assert_allclose(maze.move(np.array([-0.1, 0.1]), np.array([0.2, 0.1])), [0.1, 0.2])  # above the gap
    np.testing.assert_allclose(maze.move(np.array([0.9, 0.9]), np.array([0.2, 0.2])), [1.0, 1.0])  # the square's edge
    assert maze.is_free(np.array([[0.0, 0.5], [0.5, -0.5], [0.04, -0.5], [1.1, 0.0]])).tolist() == [True, True, False, False]
    rng = np.random.default_rng(0)
    assert maze.is_free(np.array([maze.sample_free(rng) for _ in range(500)])).all()


def test_depth_open_square_and_across() -> None:
    maze, open_square = WallMaze(), WallMaze(wall=False)
    points = np.array([[0.0, -0.5], [0.02, -0.5], [0.0, -0.01], [1.2, 0.0], [0.5, 0.5], [0.05, -0.5]])
    np.testing.assert_allclose(maze.depth(points), [0.05, 0.03, 0.01, 0.2, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(open_square.depth(points), [0.0, 0.0, 0.0, 0.2, 0.0, 0.0], atol=1e-12)
    assert open_square.is_free(points).tolist() == [True, True, True, False, True, True]
    start = np.array([-0.1, -0.5])
    np.testing.assert_allclose(open_square.move(start, np.array([0.2, 0.1])), [0.1, -0.4])  # no wall to stop it
    for env_id in (POINT, CAR):
        env = gym.make(env_id, across=True)
        for seed in range(50):
            obs, _ = env.reset(seed=seed)
            start, goal = obs["achieved_goal"], obs["desired_goal"]
            assert start[1] < 0 and goal[1] < 0 and start[0] * goal[0] < 0  # below the gap, on opposite sides
            assert min(abs(start[0]), abs(goal[0])) > 2 * maze.wall_half_width and np.abs([*start, *goal]).max() <= 0.9
    open_car = gym.make(CAR, wall=False)
    open_car.reset(seed=0, options={"start": (-0.5, -0.5), "goal": (0.5, -0.5)})
    open_car.unwrapped.heading = 0.0
    for _ in range(5):  # straight through where the wall would be
        obs, reward, *_ = open_car.step(np.array([1.0, 0.0]))
    np.testing.assert_allclose(obs["achieved_goal"], [0.5, -0.5], atol=1e-6)
    assert reward == 0.0


def test_car_drives_and_turns_as_maze2d_car_but_meets_the_wall() -> None:
    env = WallMaze2DCarEnv()
    env.reset(seed=0, options={"start": (-0.5, -0.5), "goal": (0.5, -0.5)})
    env.heading = 0.0  # facing +x, the wall ahead
    obs, *_ = env.step(np.array([1.0, 0.0]))
    np.testing.assert_allclose(obs["observation"], [-0.3, -0.5, 1.0, 0.0], atol=1e-6)
    obs, *_ = env.step(np.array([0.0, 1.0]))  # a turn alone does not move
    np.testing.assert_allclose(obs["observation"], [-0.3, -0.5, np.cos(np.pi / 4), np.sin(np.pi / 4)], atol=1e-6)
    env.position, env.heading = np.array([-0.1, -0.5]), 0.0
    obs, reward, *_ = env.step(np.array([1.0, 0.0]))  # into the wall: blocked
    np.testing.assert_allclose(obs["achieved_goal"], [-0.1, -0.5], atol=1e-6)
    assert reward == -1.0
    car = gym.make(CAR)
    car.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(300):
        obs, _, _, truncated, _ = car.step(rng.uniform(-1, 1, size=2))
        assert WallMaze().is_free(obs["achieved_goal"])
        if truncated:
            car.reset()


def test_car_has_the_points_starts_and_goals() -> None:
    car, point = gym.make(CAR), gym.make(POINT)
    for seed in range(3):
        car_obs, _ = car.reset(seed=seed)
        point_obs, _ = point.reset(seed=seed)
        np.testing.assert_array_equal(car_obs["desired_goal"], point_obs["desired_goal"])
        np.testing.assert_array_equal(car_obs["achieved_goal"], point_obs["achieved_goal"])


def test_a_point_planner_serves_the_car_not_the_u_maze(tmp_path) -> None:
    path = tmp_path / "wall.pt"
    GoalPlanner(2, net_arch=[8], metadata={"source_task": POINT}).save(path)
    env = PilotBonusWrapper(gym.make(CAR), path)
    env.reset(seed=0)
    assert -2.0 <= env.step(env.action_space.sample())[1] <= 1.0
    LandmarkGuidance(gym.make(CAR), path).reset(seed=0)
    with pytest.raises(ValueError, match="goal space"):
        PilotBonusWrapper(gym.make("Pilot/Maze2DCar-v0"), path)


@pytest.mark.parametrize(
    ("env_id", "kwargs", "match"),
    [
        (POINT, {"step_size": 0.0}, "step_size"),
        (POINT, {"gap_y": 1.0}, "gap_y"),
        (POINT, {"wall_half_width": -0.1}, "wall_half_width"),
        (POINT, {"render_mode": "human"}, "render_mode"),
        (CAR, {"max_speed": 1.0}, "max_speed"),
        (CAR, {"max_turn": 0.0}, "max_turn"),
        (CAR, {"gap_y": -1.0}, "gap_y"),
        (CAR, {"across": True, "gap_y": -0.95}, "across"),
    ],
)
def test_bad_arguments(env_id: str, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        gym.make(env_id, **kwargs)


def test_wall_maze_car_challenge_smoke(tmp_path) -> None:
    """SAC + HER teacher on the point -> planner from its rollouts -> HER + bonus on the car, vs SAC + HER."""
    from sb3_pilot.experiments.challenges import CHALLENGES, run_challenge

    summary = run_challenge("wall-maze-car", "smoke", root=tmp_path)
    stages = {stage.name: stage for stage in CHALLENGES["wall-maze-car"].stages}
    assert set(summary["methods"]) == {stage.method for stage in CHALLENGES["wall-maze-car"].stages if stage.method}
    assert all(result["env_id"] == CAR for result in summary["methods"].values())
    teacher = summary["stages"]["seed_0/teacher"]["config"]["zoo"]
    assert teacher[:5] == ["train", "--algo", "sac", "--env", POINT] and "cpu/sac.yml" in teacher
    planner_path = tmp_path / "wall-maze-car" / "models" / "seed_0" / "distill" / "planner.pt"
    planner = GoalPlanner.load(planner_path)
    assert planner.metadata["teacher_algorithm"] == "SAC" and planner.metadata["labels"] == "rollouts"
    assert planner.source_task == POINT and planner.metadata["teacher_num_timesteps"] == 300
    bonus = " ".join(summary["stages"]["seed_0/pilot_disp"]["config"]["zoo"])
    assert "sb3_pilot.PilotBonusWrapper" in bonus and "displacement_cosine" in bonus and "planner.pt" in bonus
    # zero-shot: the controller trained on the open square, evaluated across the wall, guided and not
    assert summary["stages"]["seed_0/controller"]["config"]["zoo"][-2:] == ["--env-kwargs", "wall:False"]
    guided = summary["stages"]["seed_0/guided"]["config"]
    assert guided["planner"].endswith("planner.pt") and guided["horizon"] == 1 and guided["env_kwargs"] == {"across": True}
    assert summary["stages"]["seed_0/unguided"]["config"]["planner"] is None
    unguided = summary["methods"][stages["unguided"].method]
    assert summary["methods"][stages["guided"].method]["baseline"] == stages["unguided"].method and "baseline" not in unguided
    for episode in json.loads((tmp_path / "wall-maze-car" / "models" / "seed_0" / "guided" / "guidance.json").read_text())[
        "episodes"
    ]:
        start, goal, landmark = episode["achieved_goals"][0], episode["desired_goal"], episode["landmarks"][0]
        assert start[1] < 0 and goal[1] < 0 and start[0] * goal[0] < 0 and landmark != goal
