"""The Ant controller's pieces: AntLocomotionEnv's guidance-training options and GoalRelativeExtractor."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
import yaml

from sb3_pilot.common.torch_layers import GoalRelativeExtractor, quaternion_yaw, remove_yaw
from sb3_pilot.envs import register_envs
from sb3_pilot.envs.locomotion import LOCOMOTION_GOAL_RADIUS, ant_up_z

register_envs()
OPTIONS = {
    "goal_range": (0.5, 3.0),
    "goal_hold_steps": 2,
    "distance_threshold": 0.5,
    "reward_type": "dense",
    "terminate_when_flipped": True,
}


def _quaternion_product(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def test_defaults_keep_the_task():
    """Without options, the task is the paper's: goals in the radius-2 disk, sparse reward, info, no termination."""
    plain, explicit = (
        gym.make("Pilot/AntLocomotion-v0"),
        gym.make("Pilot/AntLocomotion-v0", goal_range=None, goal_hold_steps=None, reward_type="sparse"),
    )
    assert plain.spec.max_episode_steps == 100
    assert plain.unwrapped.distance_threshold == 0.1
    for seed in range(3):
        obs, info = plain.reset(seed=seed)
        obs_b, _ = explicit.reset(seed=seed)
        assert np.linalg.norm(obs["desired_goal"]) <= LOCOMOTION_GOAL_RADIUS
        np.testing.assert_array_equal(obs["desired_goal"], obs_b["desired_goal"])
        assert info == {"is_success": False}
        action = np.ones(8, dtype=np.float32)
        obs, reward, terminated, truncated, info = plain.step(action)
        assert reward == -1.0 and not terminated and not truncated and info == {"is_success": False}


def test_goal_range_and_moving_goal():
    env = gym.make("Pilot/AntLocomotion-v0", max_episode_steps=500, **OPTIONS)
    assert env.spec.max_episode_steps == 500
    ant = env.unwrapped
    ant.init_qpos[:2] = [4.0, -3.0]  # goals are drawn around the Ant, wherever it starts
    obs, _ = env.reset(seed=0)
    distance = np.linalg.norm(obs["desired_goal"] - obs["achieved_goal"])
    assert 0.5 <= distance <= 3.0
    # put the goal under the Ant: reached for hold_steps + 1 steps, then a new goal is drawn around it
    goal = obs["achieved_goal"].astype(np.float64)
    ant.goal = goal.copy()
    action = np.zeros(8, dtype=np.float32)
    for step in range(3):
        obs, reward, terminated, _, info = env.step(action)
        assert info["is_success"] and not terminated
        assert info["goals_reached"] == (1 if step == 2 else 0)
        assert reward > 1.5  # upright + at the goal, nearly still
    assert not np.allclose(obs["desired_goal"], goal)
    assert 0.5 - 0.05 <= np.linalg.norm(obs["desired_goal"] - obs["achieved_goal"]) <= 3.0 + 0.05


def test_dense_reward_is_progress():
    env = gym.make("Pilot/AntLocomotion-v0", **{**OPTIONS, "goal_reward": 0.0, "upright_reward": 0.0, "ctrl_cost_weight": 0.0})
    ant = env.unwrapped
    env.reset(seed=1)
    before = ant.distance_to_goal()
    _, reward, *_ = env.step(env.action_space.sample())
    assert reward == pytest.approx((before - ant.distance_to_goal()) / ant.dt)


def test_flip_terminates_only_when_asked():
    for terminate in (True, False):
        env = gym.make("Pilot/AntLocomotion-v0", **{**OPTIONS, "terminate_when_flipped": terminate})
        env.reset(seed=0)
        ant = env.unwrapped
        qpos, qvel = ant.data.qpos.copy(), ant.data.qvel.copy()
        qpos[3:7] = [0.0, 1.0, 0.0, 0.0]  # turned by pi about x: on its back
        qpos[2] = 0.3
        ant.set_state(qpos, qvel)
        assert ant_up_z(ant.data.qpos) == pytest.approx(-1.0) and ant.flipped
        _, reward, terminated, _, info = env.step(np.zeros(8, dtype=np.float32))
        assert info["flipped"] and terminated == terminate
        assert reward < 1.0  # no upright reward


def test_flip_up_z_counts_a_tilt_as_flipped():
    """Tilted 70 degrees (up-axis z about 0.34): flipped under flip_up_z=0.5, not under the default 0."""
    tilt, rewards = np.deg2rad(70.0), []
    for flip_up_z, flipped in ((0.5, True), (0.0, False)):
        env = gym.make("Pilot/AntLocomotion-v0", **{**OPTIONS, "flip_up_z": flip_up_z})
        env.reset(seed=0)
        ant = env.unwrapped
        qpos, qvel = ant.data.qpos.copy(), np.zeros_like(ant.data.qvel)
        qpos[3:7] = [np.cos(tilt / 2), np.sin(tilt / 2), 0.0, 0.0]  # turned by 70 degrees about x
        qpos[2] = 2.0  # in the air, at rest: the tilt stays for the step
        ant.set_state(qpos, qvel)
        assert ant_up_z(ant.data.qpos) == pytest.approx(np.cos(tilt)) and ant.flipped == flipped
        _, reward, terminated, _, info = env.step(np.zeros(8, dtype=np.float32))
        assert 0.0 < ant_up_z(ant.data.qpos) < 0.5
        assert info["flipped"] == terminated == flipped
        rewards.append(reward)
    assert rewards[1] - rewards[0] == pytest.approx(OPTIONS.get("upright_reward", 1.0))  # upright only if not flipped


def test_option_errors():
    with pytest.raises(ValueError, match="goal_range"):
        gym.make("Pilot/AntLocomotion-v0", goal_range=(2.0, 1.0))
    with pytest.raises(ValueError, match="reward_type"):
        gym.make("Pilot/AntLocomotion-v0", reward_type="shaped")
    with pytest.raises(ValueError, match="flip_up_z"):
        gym.make("Pilot/AntLocomotion-v0", flip_up_z=1.0)


def _features(extractor: GoalRelativeExtractor, obs: dict[str, np.ndarray]) -> th.Tensor:
    return extractor({key: th.as_tensor(np.asarray(value, dtype=np.float32))[None] for key, value in obs.items()})


def _moving_ant_obs() -> dict[str, np.ndarray]:
    env = gym.make("Pilot/AntLocomotion-v0", max_episode_steps=500, **OPTIONS)
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(15):
        obs, *_ = env.step(rng.uniform(-1, 1, size=8).astype(np.float32))
    return obs


def test_extractor_ignores_position_and_heading():
    obs = _moving_ant_obs()
    space = gym.make("Pilot/AntLocomotion-v0").observation_space
    extractor = GoalRelativeExtractor(space)
    assert extractor.features_dim == 30
    reference = _features(extractor, obs)
    shift = np.array([-4.0, 4.5])
    shifted = {
        "observation": np.concatenate([obs["observation"][:2] + shift, obs["observation"][2:]]),
        "achieved_goal": obs["achieved_goal"] + shift,
        "desired_goal": obs["desired_goal"] + shift,
    }
    th.testing.assert_close(_features(extractor, shifted), reference, atol=1e-5, rtol=0)
    # the whole scene turned by an angle about z (positions, torso orientation, world-frame velocity, goals)
    angle = 2.1
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    turned = obs["observation"].astype(np.float64).copy()
    turned[:2] = rotation @ turned[:2]
    turned[3:7] = _quaternion_product(np.array([np.cos(angle / 2), 0, 0, np.sin(angle / 2)]), turned[3:7])
    turned[15:17] = rotation @ turned[15:17]
    rotated = {
        "observation": turned,
        "achieved_goal": turned[:2],
        "desired_goal": rotation @ obs["desired_goal"].astype(np.float64),
    }
    th.testing.assert_close(_features(extractor, rotated), reference, atol=1e-4, rtol=0)
    # ... but the goal's direction relative to the Ant matters (the test can fail)
    moved_goal = {**obs, "desired_goal": obs["achieved_goal"] + (rotation @ (obs["desired_goal"] - obs["achieved_goal"]))}
    assert (_features(extractor, moved_goal) - reference).abs().max() > 0.1


def test_extractor_clips_far_goals_and_drops_position():
    obs = _moving_ant_obs()
    extractor = GoalRelativeExtractor(gym.make("Pilot/AntLocomotion-v0").observation_space, max_goal_distance=3.0)
    direction = obs["desired_goal"] - obs["achieved_goal"]
    far = {**obs, "desired_goal": obs["achieved_goal"] + 10 * direction / np.linalg.norm(direction)}
    farther = {**obs, "desired_goal": obs["achieved_goal"] + 20 * direction / np.linalg.norm(direction)}
    th.testing.assert_close(_features(extractor, far), _features(extractor, farther))
    assert _features(extractor, far)[0, -1].item() == pytest.approx(3.0)
    plain = GoalRelativeExtractor(gym.make("Pilot/AntLocomotion-v0").observation_space, quaternion_index=None)
    features = _features(plain, obs)
    np.testing.assert_allclose(features[0, :27].numpy(), obs["observation"][2:], rtol=1e-6)


def test_yaw_helpers():
    yaw = th.tensor([0.3, -2.5])
    quaternion = th.stack([th.cos(yaw / 2), th.zeros(2), th.zeros(2), th.sin(yaw / 2)], dim=-1)
    th.testing.assert_close(quaternion_yaw(quaternion), yaw)
    th.testing.assert_close(remove_yaw(quaternion, yaw), th.tensor([[1.0, 0, 0, 0], [1.0, 0, 0, 0]]), atol=1e-6, rtol=0)


@pytest.mark.parametrize(("conf_file", "flip_up_z"), [("ant_controller.yml", 0.0), ("ant_controller_upright.yml", 0.5)])
def test_recipe_builds_the_model(conf_file: str, flip_up_z: float):
    """The YAML's env_kwargs make the env and its policy_kwargs string (evaluated as the zoo does) the policy."""
    from stable_baselines3 import SAC

    recipe = yaml.safe_load((Path(__file__).parent.parent / "hyperparams" / "cpu" / conf_file).read_text())
    entry = recipe["Pilot/AntLocomotion-v0"]
    env = gym.make("Pilot/AntLocomotion-v0", **entry["env_kwargs"])
    assert env.spec.max_episode_steps == 500 and env.unwrapped.reward_type == "dense"
    assert env.unwrapped.flip_up_z == flip_up_z
    policy_kwargs = eval(entry["policy_kwargs"])
    assert policy_kwargs["features_extractor_class"] is GoalRelativeExtractor
    model = SAC("MultiInputPolicy", env, policy_kwargs=policy_kwargs, buffer_size=10, device="cpu")
    assert model.actor.features_extractor.features_dim == 30


def test_wall_margin_wrapper_rewards_are_relabelable():
    from sb3_pilot.experiments.ant_controller import WallMarginWrapper, umaze_wall_distance

    np.testing.assert_allclose(
        umaze_wall_distance(np.array([[-4.0, 4.0], [-4.0, 2.5], [3.0, 3.0], [0.0, 0.0]])), [2, 0.5, np.sqrt(2), 0]
    )
    env = WallMarginWrapper(gym.make("Pilot/Maze2D-v0"), margin=1.0, cost=1.0)
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        obs, reward, _, _, info = env.step(env.action_space.sample())
        assert reward == env.compute_reward(obs["achieved_goal"], obs["desired_goal"], info)
    achieved = np.array([[-4.0, 4.0], [-4.0, 2.5], [-4.0, 2.5]], dtype=np.float32)
    desired = np.array([[4.0, 4.0], [4.0, 4.0], [-4.0, 2.0]], dtype=np.float32)
    np.testing.assert_array_equal(env.compute_reward(achieved, desired, None), [-1, -2, 0])  # the goal is never penalised


def test_load_controller_of_a_her_model(tmp_path: Path) -> None:
    """
    A goal-conditioned controller trained with HER (Complex-Morph's HER+PILoT Ant, a user's own) loads for guidance
    without its env: the policy alone, the same actions as the trained model.
    """
    from stable_baselines3 import SAC, HerReplayBuffer

    from sb3_pilot.experiments.ant_controller import load_controller

    env = gym.make("Pilot/AntLocomotion-v0", max_episode_steps=20)
    model = SAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, learning_starts=40, batch_size=16, seed=0)
    model.learn(60)
    model.save(tmp_path / "her_controller")
    loaded = load_controller(tmp_path / "her_controller.zip")
    observation, _ = env.reset(seed=0)
    np.testing.assert_allclose(
        loaded.predict(observation, deterministic=True)[0], model.predict(observation, deterministic=True)[0], atol=1e-6
    )
