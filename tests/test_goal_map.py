"""Goal spaces related by a known map: GoalMap, share_goal_space(goal_map=...), the bonus, HER and the guidance."""

import gymnasium as gym
import gymnasium_robotics
import numpy as np
import pytest
from stable_baselines3 import SAC, HerReplayBuffer

from sb3_pilot import UDPO, GoalMap, LandmarkGuidance, PilotBonusWrapper, PilotHerReplayBuffer, distill_goal_planner
from sb3_pilot.distill import goal_planner as planner_module
from sb3_pilot.distill import share_goal_space
from sb3_pilot.transfer.bonus import cosine_similarity

gym.register_envs(gymnasium_robotics)
SOURCE, TARGET = "PointMaze_UMaze-v3", "AntMaze_UMaze-v5"
#: gymnasium-robotics' maze_size_scaling: 1 for PointMaze_*, 4 for AntMaze_*, both mazes centred on the map
MAZE_SCALE = 4.0


@pytest.fixture(scope="module")
def point_maze_planner():
    """A tiny planner distilled from a briefly trained UDPO on the registered PointMaze_UMaze-v3."""
    model = UDPO(
        "MultiInputPolicy",
        gym.make(SOURCE, max_episode_steps=50),
        replay_buffer_class=HerReplayBuffer,
        learning_starts=100,
        batch_size=32,
        policy_kwargs={"net_arch": [32, 32]},
        seed=0,
    )
    model.learn(200)
    env = gym.make(SOURCE, max_episode_steps=50)
    # 200 steps teach no goal: the planner tests the map's plumbing, not its landmarks
    kwargs = {"n_samples": 400, "gradient_steps": 50, "batch_size": 32, "net_arch": [16], "allow_unsuccessful_teacher": True}
    return distill_goal_planner(model, **kwargs, env=env)


@pytest.fixture
def maze_map(monkeypatch):
    """``AntMaze_UMaze-v5`` goals are 4x ``PointMaze_UMaze-v3``'s, declared for this test only."""
    monkeypatch.setattr(planner_module, "GOAL_MAPS", {})
    share_goal_space(SOURCE, TARGET, goal_map=GoalMap(MAZE_SCALE))


def test_goal_map_maps_and_inverts():
    goals = np.array([[1.0, -2.0], [0.5, 3.0]], dtype=np.float32)
    for goal_map in (GoalMap(4.0, 1.0), GoalMap([2.0, -1.0], [0.5, 0.0]), GoalMap([[0.0, -2.0], [1.0, 0.0]], 3.0)):
        mapped = goal_map(goals)
        assert mapped.dtype == np.float32 and mapped.shape == goals.shape
        np.testing.assert_allclose(goal_map.inverse()(mapped), goals, atol=1e-6)
        assert goal_map.inverse().inverse() is goal_map
    np.testing.assert_allclose(GoalMap([[0.0, -2.0], [1.0, 0.0]], 3.0)(goals[0]), [7.0, 4.0])
    for matrix, offset, match in (
        (0.0, 0.0, "invertible"),
        ([[1.0, 2.0], [2.0, 4.0]], 0.0, "invertible"),
        (np.ones((2, 3)), 0.0, "square"),
        ([1.0, 2.0], [0.0, 0.0, 0.0], "different sizes"),
        (np.nan, 0.0, "finite"),
    ):
        with pytest.raises(ValueError, match=match):
            GoalMap(matrix, offset)


def test_share_goal_space_with_a_map_refusals(monkeypatch):
    monkeypatch.setattr(planner_module, "GOAL_MAPS", {})
    monkeypatch.setattr(planner_module, "SHARED_GOAL_SPACES", [frozenset({"A", "B"})])
    with pytest.raises(ValueError, match="two different tasks"):
        share_goal_space("A", "C", "D", goal_map=GoalMap(2.0))
    with pytest.raises(ValueError, match="already share"):
        share_goal_space("A", "B", goal_map=GoalMap(2.0))
    share_goal_space("A", "C", goal_map=GoalMap(2.0, 1.0))
    share_goal_space("A", "C", goal_map=GoalMap(2.0, 1.0))  # the same map again: nothing changes
    with pytest.raises(ValueError, match="already share"):
        share_goal_space("A", "C", goal_map=GoalMap(2.0, 0.5))
    assert planner_module.goal_map_between("A", "B") is None
    np.testing.assert_allclose(planner_module.goal_map_between("C", "A")(np.array([5.0, 3.0])), [2.0, 1.0])
    with pytest.raises(ValueError, match="already share"):
        share_goal_space("C", "A")
    with pytest.raises(ValueError, match="not declared"):
        planner_module.goal_map_between("A", "D")


def test_point_maze_planner_on_ant_maze_needs_the_map(point_maze_planner, maze_map, monkeypatch):
    env = gym.make(TARGET, max_episode_steps=50)
    wrapper = PilotBonusWrapper(env, point_maze_planner)
    assert isinstance(wrapper.goal_map, GoalMap)
    obs, _ = wrapper.reset(seed=0)
    achieved, desired = obs["achieved_goal"], obs["desired_goal"]
    # AntMaze's U-maze spans [-10, 10]^2 (5 cells of 4), PointMaze's [-2.5, 2.5]^2: these goals are AntMaze's
    assert np.abs(desired).max() > 2.5 and np.abs(desired).max() <= 10
    planner_landmark = point_maze_planner.predict(achieved / MAZE_SCALE, desired / MAZE_SCALE)
    mapped = MAZE_SCALE * planner_landmark
    landmark = wrapper.goal_map.through(point_maze_planner.predict, achieved, desired)
    np.testing.assert_allclose(landmark, mapped, rtol=1e-5)
    assert np.abs(landmark).max() <= 10  # inside AntMaze's maze, a step 4x the planner's own step in PointMaze
    step = np.linalg.norm(planner_landmark - achieved / MAZE_SCALE)
    assert np.linalg.norm(landmark - achieved) == pytest.approx(MAZE_SCALE * step, rel=1e-4)
    unmapped = point_maze_planner.predict(achieved, desired)  # AntMaze coordinates fed to a PointMaze planner
    assert not np.allclose(unmapped, mapped, atol=1e-3)

    next_obs, reward, *_ = wrapper.step(wrapper.action_space.sample())
    moved = next_obs["achieved_goal"] - achieved
    expected = cosine_similarity(moved, mapped - achieved)
    assert reward == pytest.approx(float(env.unwrapped.compute_reward(next_obs["achieved_goal"], desired, {})) + expected)
    assert abs(expected - cosine_similarity(moved, unmapped - achieved)) > 1e-3  # the map changes the bonus

    monkeypatch.setattr(planner_module, "GOAL_MAPS", {})
    with pytest.raises(ValueError, match="GoalMap"):
        PilotBonusWrapper(env, point_maze_planner)
    with pytest.raises(ValueError, match="GoalMap"):
        LandmarkGuidance(env, point_maze_planner)


def test_her_relabelled_bonus_goes_through_the_map(point_maze_planner, maze_map):
    """PilotHerReplayBuffer recomputes the bonus for relabelled goals: through the map, as at the step."""
    env = PilotBonusWrapper(gym.make(TARGET, max_episode_steps=20), point_maze_planner)
    model = SAC(
        "MultiInputPolicy",
        env,
        replay_buffer_class=PilotHerReplayBuffer,
        learning_starts=60,
        batch_size=16,
        policy_kwargs={"net_arch": [16]},
        seed=0,
    )
    model.learn(60)
    samples = model.replay_buffer.sample(64, env=model.get_vec_normalize_env())
    previous = samples.observations["achieved_goal"].cpu().numpy()
    achieved = samples.next_observations["achieved_goal"].cpu().numpy()
    desired = samples.next_observations["desired_goal"].cpu().numpy()
    assert not np.allclose(desired, desired[0])  # relabelled goals among them
    landmark = MAZE_SCALE * point_maze_planner.predict(previous / MAZE_SCALE, desired / MAZE_SCALE)
    sparse = env.unwrapped.compute_reward(achieved, desired, {})
    expected = sparse + cosine_similarity(achieved - previous, landmark - previous)
    np.testing.assert_allclose(samples.rewards.cpu().numpy().ravel(), expected, atol=1e-5)


def test_guidance_landmarks_go_through_the_map(point_maze_planner, maze_map):
    env = LandmarkGuidance(gym.make(TARGET, max_episode_steps=10), point_maze_planner, horizon=3, switch_distance=0)
    obs, _ = env.reset(seed=1)
    for _ in range(3):
        achieved, desired = env.episode_achieved_goals[-1], env.real_desired_goal
        planned = MAZE_SCALE * point_maze_planner.plan(achieved / MAZE_SCALE, desired / MAZE_SCALE, 3, snap=False)[-1]
        np.testing.assert_allclose(obs["desired_goal"], planned, rtol=1e-5)
        obs, *_ = env.step(env.action_space.sample())
