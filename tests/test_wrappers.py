"""PilotBonusWrapper (reward bonus, HER consistency), PilotHerReplayBuffer and LandmarkGuidance."""

import numpy as np
import pytest
import torch as th
from goal_envs import PointGoalEnv
from maze_envs import WallMazeEnv, train_udpo
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_pilot.distill import GoalPlanner, distill_goal_planner
from sb3_pilot.distill import goal_planner as planner_module
from sb3_pilot.transfer import LandmarkGuidance, PilotBonusWrapper, PilotHerReplayBuffer
from sb3_pilot.transfer.bonus import PREVIOUS_ACHIEVED_GOAL, SIMILARITIES, cosine_similarity, planned_progress


def make_planner(source_task: str = "WallMazeEnv", goal_dim: int = 2, seed: int = 0) -> GoalPlanner:
    """An untrained planner: HER consistency holds for any planner."""
    th.manual_seed(seed)
    return GoalPlanner(goal_dim, net_arch=[16], metadata={"source_task": source_task})


def constant_planner(move: np.ndarray, source_task: str = "WallMazeEnv") -> GoalPlanner:
    """A planner whose landmark is always ``achieved_goal + move``."""
    planner = GoalPlanner(len(move), net_arch=[4], metadata={"source_task": source_task})
    with th.no_grad():
        for param in planner.parameters():
            param.zero_()
        planner.net[-1].bias[: len(move)] = th.as_tensor(move, dtype=th.float32)
    return planner


def run_episode(env, buffer, seed: int, rng: np.random.Generator):
    """Random-action episode stored in ``buffer`` (as SB3 stores it); returns start, actions, rewards."""
    obs, _ = env.reset(seed=seed)
    start, actions, rewards, done = obs["achieved_goal"].copy(), [], [], False
    while not done:
        action = rng.uniform(-1, 1, size=2).astype(np.float32)
        next_obs, reward, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        buffer.add(
            {key: value[None] for key, value in obs.items()},
            {key: value[None] for key, value in next_obs.items()},
            action[None],
            np.array([reward]),
            np.array([done]),
            [info],
        )
        actions.append(action)
        rewards.append(reward)
        obs = next_obs
    return start, np.array(actions), np.array(rewards)


def make_buffer(env, buffer_class=PilotHerReplayBuffer, **kwargs):
    return buffer_class(200, env.observation_space, env.action_space, env=DummyVecEnv([lambda: env]), **kwargs)


@pytest.mark.parametrize("similarity", SIMILARITIES)
def test_her_relabelled_reward_equals_online_reward(similarity):
    env = PilotBonusWrapper(WallMazeEnv(), make_planner(), beta=0.5, similarity=similarity)
    buffer = make_buffer(env)
    start, actions, stored_rewards = run_episode(env, buffer, seed=1, rng=np.random.default_rng(0))
    np.random.seed(0)
    samples = buffer.sample(256)
    n_real = 256 - int(buffer.her_ratio * 256)
    checked, relabelled_differs = 0, False
    for i in range(n_real, 256, 8):
        step = int(np.flatnonzero((actions == samples.actions[i].numpy()).all(axis=1))[0])
        goal = samples.observations["desired_goal"][i].numpy()
        # Online: the same start and actions, with the relabelled goal as the episode's goal
        replay = PilotBonusWrapper(WallMazeEnv(), env.planner, beta=0.5, similarity=similarity)
        replay.reset(options={"start": start, "goal": goal})
        for action in actions[: step + 1]:
            _, online_reward, *_ = replay.step(action)
        np.testing.assert_allclose(samples.rewards[i].item(), online_reward, rtol=1e-5, atol=1e-5)
        relabelled_differs |= abs(online_reward - stored_rewards[step]) > 1e-3
        checked += 1
    assert checked >= 20
    assert relabelled_differs, "relabelled goals should change the bonus"


def test_pilot_buffer_matches_copied_infos_and_plain_her_raises():
    env = PilotBonusWrapper(WallMazeEnv(), make_planner(), beta=1.0)
    rewards = []
    for buffer_class, kwargs in [(PilotHerReplayBuffer, {}), (HerReplayBuffer, {"copy_info_dict": True})]:
        buffer = make_buffer(env, buffer_class, **kwargs)
        run_episode(env, buffer, seed=2, rng=np.random.default_rng(1))
        np.random.seed(3)
        rewards.append(buffer.sample(64).rewards.numpy())
    np.testing.assert_allclose(rewards[0], rewards[1], rtol=1e-6)

    plain = make_buffer(env, HerReplayBuffer)
    run_episode(env, plain, seed=2, rng=np.random.default_rng(1))
    with pytest.raises(ValueError, match="PilotHerReplayBuffer"):
        plain.sample(64)
    with pytest.raises(ValueError, match="copy_info_dict"):
        make_buffer(env, PilotHerReplayBuffer, copy_info_dict=True)


def test_online_reward_is_sparse_plus_beta_bonus():
    env = PilotBonusWrapper(WallMazeEnv(), make_planner(), beta=0.7)
    obs, _ = env.reset(seed=0)
    for _ in range(10):
        previous = obs["achieved_goal"].copy()
        obs, reward, _, _, info = env.step(env.action_space.sample())
        np.testing.assert_array_equal(info[PREVIOUS_ACHIEVED_GOAL], previous)
        sparse = env.unwrapped.compute_reward(obs["achieved_goal"], obs["desired_goal"], {})
        bonus = env.bonus(previous, obs["achieved_goal"], obs["desired_goal"])
        assert reward == pytest.approx(sparse + 0.7 * bonus)
        assert reward == pytest.approx(env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info))


def test_similarities():
    move = np.array([0.1, 0.0], dtype=np.float32)
    previous = np.array([[0.5, 0.5]] * 3, dtype=np.float32)
    achieved = previous + np.array([[0.1, 0.0], [-0.1, 0.0], [0.0, 0.0]], dtype=np.float32)
    desired = np.zeros_like(previous)
    for offset in (0.0, 3.0):
        env = PilotBonusWrapper(WallMazeEnv(offset=offset), constant_planner(move), similarity="displacement_cosine")
        # Towards the landmark: 1, away: -1, not moving: 0, wherever the origin lies
        np.testing.assert_allclose(env.bonus(previous + offset, achieved + offset, desired), [1, -1, 0], atol=1e-6)
    paper = PilotBonusWrapper(WallMazeEnv(), constant_planner(move), similarity="goal_cosine")
    # The paper's cosine of goal vectors barely tells moving towards the landmark from moving away
    bonus = paper.bonus(previous, achieved, desired)
    assert bonus[0] > bonus[1] and bonus[0] - bonus[1] < 0.2


def test_planned_progress_measures_the_move_along_the_plan():
    planned = np.array([0.2, 0.0], dtype=np.float32)
    previous = np.array([[0.5, 0.5]] * 6, dtype=np.float32)
    moves = np.array([[0.1, 0.0], [0.1, 0.3], [-0.05, 0.0], [0.0, 0.1], [0.6, 0.0], [-0.6, 0.0]], dtype=np.float32)
    desired = np.zeros_like(previous)
    for offset in (0.0, 3.0):
        env = PilotBonusWrapper(WallMazeEnv(offset=offset), constant_planner(planned), similarity="planned_progress")
        bonus = env.bonus(previous + offset, previous + moves + offset, desired)
        # half the planned step, also with a sideways part; a quarter back; sideways only; clipped past one step
        np.testing.assert_allclose(bonus, [0.5, 0.5, -0.25, 0.0, 1.0, -1.0], atol=1e-6)
    # two slow moves forward and a fast one back earn nothing over the cycle; the displacement cosine pays 1 for it
    cycle = np.array([[0.05, 0.0], [0.05, 0.0], [-0.1, 0.0]], dtype=np.float32)
    assert planned_progress(cycle, np.stack([planned] * 3)).sum() == pytest.approx(0.0)
    assert cosine_similarity(cycle, np.stack([planned] * 3)).sum() == pytest.approx(1.0)
    np.testing.assert_array_equal(planned_progress(cycle, np.zeros_like(cycle)), [0.0, 0.0, 0.0])


def test_bonus_wrapper_refusals(monkeypatch):
    with pytest.raises(ValueError, match="3-dim goals"):
        PilotBonusWrapper(WallMazeEnv(), make_planner(goal_dim=3))
    with pytest.raises(ValueError, match="distilled on 'PointGoalEnv'"):
        PilotBonusWrapper(WallMazeEnv(), make_planner(source_task="PointGoalEnv"))
    monkeypatch.setattr(planner_module, "SHARED_GOAL_SPACES", [])
    planner_module.share_goal_space("PointGoalEnv", "WallMazeEnv")
    PilotBonusWrapper(WallMazeEnv(), make_planner(source_task="PointGoalEnv"))
    with pytest.raises(ValueError, match="beta"):
        PilotBonusWrapper(WallMazeEnv(), make_planner(), beta=-1.0)
    with pytest.raises(ValueError, match="similarity"):
        PilotBonusWrapper(WallMazeEnv(), make_planner(), similarity="euclidean")
    with pytest.raises(ValueError, match="no 'source_task'"):
        PilotBonusWrapper(WallMazeEnv(), GoalPlanner(2))
    with pytest.raises(ValueError, match="horizon"):
        LandmarkGuidance(WallMazeEnv(), make_planner(), horizon=0)


@pytest.fixture(scope="module")
def point_teacher_and_planner():
    model = train_udpo(PointGoalEnv, total_timesteps=3000)
    return model, distill_goal_planner(model, n_samples=10_000, gradient_steps=1000, net_arch=[64, 64])


def test_guidance_feeds_landmarks_and_judges_the_real_goal(point_teacher_and_planner):
    controller, planner = point_teacher_and_planner
    env = LandmarkGuidance(PointGoalEnv(), planner, horizon=3, switch_distance=0.2, snap=True)
    guided_steps, successes = 0, []
    for episode in range(4):
        obs, _ = env.reset(seed=episode)
        real_goal = env.unwrapped.goal.astype(np.float32)
        done = False
        while not done:
            achieved = obs["achieved_goal"]
            far = np.linalg.norm(achieved - real_goal) > 0.2
            expected = planner.plan(achieved, real_goal, horizon=3, snap=True)[-1] if far else real_goal
            np.testing.assert_allclose(obs["desired_goal"], expected, rtol=1e-6)
            guided_steps += int(far)
            action, _ = controller.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            real_success = np.linalg.norm(obs["achieved_goal"] - real_goal) <= 0.1
            assert info["is_success"] == real_success and reward == float(real_success) - 1.0
            np.testing.assert_array_equal(info["real_desired_goal"], real_goal)
        successes.append(real_success)
        assert env.episode_landmarks.shape == env.episode_achieved_goals.shape == (26, 2)
    assert guided_steps > 0
    support = planner.support.numpy()
    landmarks = env.episode_landmarks[np.linalg.norm(env.episode_landmarks - real_goal, axis=1) > 0]
    assert all((support == landmark).all(axis=1).any() for landmark in landmarks)

    unsnapped = LandmarkGuidance(PointGoalEnv(), planner, horizon=3, switch_distance=0.0)
    obs, _ = unsnapped.reset(seed=0)
    real_goal = unsnapped.unwrapped.goal.astype(np.float32)
    expected = planner.plan(obs["achieved_goal"], real_goal, horizon=3, snap=False)[-1]
    np.testing.assert_allclose(obs["desired_goal"], expected, rtol=1e-6)
    no_support = GoalPlanner(2, metadata=planner.metadata)
    with pytest.raises(ValueError, match="support goals"):
        LandmarkGuidance(PointGoalEnv(), no_support, snap=True)
    print(f"guided success rate {np.mean(successes):.2f}")
