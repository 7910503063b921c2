"""State-planner transfer across action spaces: bit-for-bit copy, freezing, VecNormalize statistics, refusals."""

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from goal_envs import PointGoalEnv
from maze_envs import WallMazeEnv, train_udpo
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_pilot import UDPO
from sb3_pilot.transfer import load_planner_from

TARGET_KWARGS = {"replay_buffer_class": HerReplayBuffer, "learning_starts": 200, "batch_size": 64, "seed": 1}


class DoubledActions(gym.ActionWrapper):
    """A 4-dim action space driving the 2-dim point: ``a[:2] - a[2:]``, clipped (a High-Dim-like target)."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)

    def action(self, action: np.ndarray) -> np.ndarray:
        return np.clip(action[:2] - action[2:], -1.0, 1.0)


@pytest.fixture(scope="module")
def source():
    return train_udpo(PointGoalEnv, total_timesteps=800)


def planner_params(model: UDPO) -> dict[str, th.Tensor]:
    return {name: value.clone() for name, value in model.policy.state_planner.state_dict().items()}


def assert_same(first: dict[str, th.Tensor], second: dict[str, th.Tensor]) -> None:
    assert first.keys() == second.keys()
    for name, value in first.items():
        assert th.equal(value, second[name]), name


def test_transfer_copies_planner_and_frozen_planner_stays_unchanged(source):
    target = load_planner_from(source, Monitor(DoubledActions(PointGoalEnv())), **TARGET_KWARGS)
    copied = planner_params(target)
    assert_same(copied, planner_params(source))
    assert target.action_space.shape == (4,)
    assert target.policy.inverse_dynamics.action_dim == 4
    assert target.policy.freeze_state_planner
    assert not any(param.requires_grad for param in target.policy.state_planner.parameters())
    inverse_dynamics = {name: value.clone() for name, value in target.policy.inverse_dynamics.state_dict().items()}
    target.learn(500)
    assert_same(planner_params(target), copied)
    learned = target.policy.inverse_dynamics.state_dict()
    assert not all(th.equal(value, learned[name]) for name, value in inverse_dynamics.items())


def test_frozen_planner_trains_neither_critics_nor_temperature(source):
    # pi(a | s, g) = I(a | s, h(s' | s, g)) with h frozen reads neither: their updates would be wasted work
    target = load_planner_from(source, Monitor(DoubledActions(PointGoalEnv())), **TARGET_KWARGS)
    critic = {name: value.clone() for name, value in target.policy.critic.state_dict().items()}
    log_ent_coef = target.log_ent_coef.detach().clone()
    target.learn(500)
    assert target._n_updates > 0
    assert_same({name: value.clone() for name, value in target.policy.critic.state_dict().items()}, critic)
    assert th.equal(target.log_ent_coef.detach(), log_ent_coef)


def test_unfrozen_planner_trains_and_path_source(source, tmp_path):
    source.save(tmp_path / "source")
    target = load_planner_from(tmp_path / "source", DoubledActions(PointGoalEnv()), freeze=False, **TARGET_KWARGS)
    assert_same(planner_params(target), planner_params(source))
    target.learn(400)
    assert not target.policy.freeze_state_planner
    changed = planner_params(target)
    assert not all(th.equal(value, changed[name]) for name, value in planner_params(source).items())


def test_vec_normalize_statistics_are_carried_over(tmp_path):
    venv = VecNormalize(DummyVecEnv([lambda: Monitor(PointGoalEnv())]), norm_reward=False, clip_obs=5.0)
    source = UDPO("MultiInputPolicy", venv, replay_buffer_class=HerReplayBuffer, learning_starts=100)
    source.learn(150)
    for source_arg, extra in [(source, {}), (tmp_path / "source", {"source_vec_normalize": tmp_path / "stats.pkl"})]:
        source.save(tmp_path / "source")
        venv.save(tmp_path / "stats.pkl")
        target = load_planner_from(source_arg, DoubledActions(PointGoalEnv()), **extra, **TARGET_KWARGS)
        target_norm = target.get_vec_normalize_env()
        assert isinstance(target_norm, VecNormalize)
        assert not target_norm.training and target_norm.clip_obs == 5.0 and not target_norm.norm_reward
        assert target_norm.action_space.shape == (4,)
        for key, stats in venv.obs_rms.items():
            assert target_norm.obs_rms[key] is not stats
            np.testing.assert_array_equal(target_norm.obs_rms[key].mean, stats.mean)
            np.testing.assert_array_equal(target_norm.obs_rms[key].var, stats.var)
        # The same raw observation reaches both planners identically scaled
        raw = {key: value[None] for key, value in PointGoalEnv().reset(seed=0)[0].items()}
        np.testing.assert_array_equal(
            target.predict_next_state(target_norm.normalize_obs(raw)), source.predict_next_state(venv.normalize_obs(raw))
        )


def test_transfer_refusals(source, tmp_path):
    with pytest.raises(ValueError, match="'observation' has shape"):
        load_planner_from(source, WallMazeEnv(), **TARGET_KWARGS)
    with pytest.raises(ValueError, match="without VecNormalize"):
        load_planner_from(source, VecNormalize(DummyVecEnv([PointGoalEnv])), **TARGET_KWARGS)
    with pytest.raises(ValueError, match="architecture"):
        load_planner_from(source, PointGoalEnv(), policy_kwargs={"net_arch": [32]}, **TARGET_KWARGS)
    with pytest.raises(ValueError, match="path"):
        load_planner_from(source, PointGoalEnv(), source_vec_normalize=tmp_path / "stats.pkl", **TARGET_KWARGS)
    (tmp_path / "not_stats.pkl").write_bytes(b"\x80\x04K\x01.")  # pickle of the int 1
    source.save(tmp_path / "source")
    with pytest.raises(ValueError, match="VecNormalize"):
        load_planner_from(tmp_path / "source", PointGoalEnv(), source_vec_normalize=tmp_path / "not_stats.pkl")
