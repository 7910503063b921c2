"""
UDPO beside SB3's SAC through the cross-algorithm checks SB3 and sb3-contrib run for their algorithms (run, spaces,
predict, save/load of the model and of the policy alone, train/eval mode, callbacks, VecNormalize, HER on a Box
bit-flipping env). Each test runs both: what SAC accepts, UDPO accepts, except what its design rules out (the README's
"Differences from SAC"): image entries in the planner state, n-step returns, gSDE.
"""

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from gymnasium import spaces
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.buffers import NStepReplayBuffer
from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.envs import BitFlippingEnv
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_pilot import UDPO
from sb3_pilot.sac import LeanSAC
from sb3_pilot.udpo import MultiInputPolicy, UDPOPolicy

ALGOS = (SAC, LeanSAC, UDPO)


def small(**overrides: Any) -> dict[str, Any]:
    """Fast settings, fresh for each model (SAC writes ``use_sde`` into the ``policy_kwargs`` dict it is given)."""
    return {"learning_starts": 50, "batch_size": 16, "policy_kwargs": {"net_arch": [16, 16]}, "seed": 0, **overrides}


class SpaceEnv(gym.Env):
    """Random observations from any space, a 2-dim Box action, 20-step episodes: what a policy must read."""

    def __init__(self, observation_space: spaces.Space):
        self.observation_space = observation_space
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.steps = 0

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.observation_space.seed(seed)
        self.steps = 0
        return self.observation_space.sample(), {}

    def step(self, action: np.ndarray):
        self.steps += 1
        return self.observation_space.sample(), float(-np.sum(np.square(action))), False, self.steps >= 20, {}


BOX64 = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float64)
OBSERVATION_SPACES = {
    "box_float64": BOX64,
    "box_2d": spaces.Box(-1.0, 1.0, shape=(2, 3), dtype=np.float32),
    "discrete": spaces.Discrete(5),
    "multi_discrete": spaces.MultiDiscrete([3, 4]),
    "multi_binary": spaces.MultiBinary(4),
    "dict_other_keys": spaces.Dict({"position": BOX64, "flags": spaces.MultiBinary(3), "mode": spaces.Discrete(2)}),
}


def policy_name(observation_space: spaces.Space) -> str:
    return "MultiInputPolicy" if isinstance(observation_space, spaces.Dict) else "MlpPolicy"


@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("space_name", OBSERVATION_SPACES)
def test_spaces_learn_predict(algo: type, space_name: str) -> None:
    """Every observation space SAC learns from: UDPO learns, and predicts on one observation and on a batch."""
    space = OBSERVATION_SPACES[space_name]
    env = SpaceEnv(space)
    model = algo(policy_name(space), env, **small()).learn(80)
    obs, _ = env.reset(seed=1)
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (2,)
    batch = {k: np.stack([v, v]) for k, v in obs.items()} if isinstance(obs, dict) else np.stack([obs, obs])
    actions, _ = model.predict(batch, deterministic=True)
    np.testing.assert_allclose(actions[0], actions[1], rtol=1e-5, atol=1e-6)  # batch rows: float reordering
    if algo is UDPO:
        assert model.predict_next_state(obs).shape == (model.policy.state_dim,)


@pytest.mark.parametrize("algo", ALGOS)
def test_hand_made_float64_predict(algo: type) -> None:
    model = algo("MlpPolicy", "Pendulum-v1", **small())
    action, _ = model.predict(np.array([0.5, -0.2, 0.1]), deterministic=True)  # float64, made by hand
    assert action.shape == (1,) and np.all(np.abs(action) <= 2.0)


@pytest.mark.parametrize("algo", ALGOS)
def test_her_on_continuous_bit_flipping(algo: type) -> None:
    """SB3's HER test env with Box actions (MultiBinary-like float observation entries)."""
    env = BitFlippingEnv(n_bits=4, continuous=True, max_steps=4)
    model = algo("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, **small(learning_starts=20))
    model.learn(60)
    assert isinstance(model.replay_buffer, HerReplayBuffer) and model.replay_buffer.size() > 0


@pytest.mark.parametrize("algo", ALGOS)
def test_save_load_model_and_policy(algo: type, tmp_path: Path) -> None:
    env = SpaceEnv(OBSERVATION_SPACES["dict_other_keys"])
    model = algo("MultiInputPolicy", env, **small()).learn(60)
    obs, _ = env.reset(seed=3)
    action, _ = model.predict(obs, deterministic=True)
    model.save(tmp_path / "model")
    model.save_replay_buffer(tmp_path / "buffer")
    loaded = algo.load(tmp_path / "model", env=env)
    loaded.load_replay_buffer(tmp_path / "buffer")
    np.testing.assert_allclose(loaded.predict(obs, deterministic=True)[0], action, rtol=1e-6)
    assert loaded.replay_buffer.size() == model.replay_buffer.size()
    loaded.learn(30)  # training continues from a loaded model
    model.policy.save(tmp_path / "policy")
    policy = type(model.policy).load(tmp_path / "policy")
    np.testing.assert_allclose(policy.predict(obs, deterministic=True)[0], action, rtol=1e-6)


class BatchNormDropoutExtractor(BaseFeaturesExtractor):
    """Flatten, batch norm and dropout: what SB3's train/eval-mode test uses."""

    def __init__(self, observation_space: spaces.Box):
        super().__init__(observation_space, int(np.prod(observation_space.shape)))
        self.net = th.nn.Sequential(th.nn.Flatten(), th.nn.BatchNorm1d(self.features_dim), th.nn.Dropout(0.5))

    def forward(self, observations: th.Tensor) -> th.Tensor:
        return self.net(observations)


@pytest.mark.parametrize("algo", ALGOS)
def test_train_eval_mode(algo: type) -> None:
    """predict runs in eval mode (no dropout, batch-norm statistics untouched); training updates the statistics."""
    policy_kwargs = {"net_arch": [16], "features_extractor_class": BatchNormDropoutExtractor}
    model = algo("MlpPolicy", "Pendulum-v1", **small(policy_kwargs=policy_kwargs))
    batch_norms = [module for module in model.policy.modules() if isinstance(module, th.nn.BatchNorm1d)]
    model.learn(60)
    stats = [norm.running_mean.clone() for norm in batch_norms]
    observation = np.array([[0.3, -0.4, 0.2]] * 4, dtype=np.float32)
    first, _ = model.predict(observation, deterministic=True)
    second, _ = model.predict(observation, deterministic=True)
    np.testing.assert_array_equal(first, second)
    assert all(th.equal(norm.running_mean, stat) for norm, stat in zip(batch_norms, stats, strict=True))
    model.policy.set_training_mode(True)
    targets = set(model.policy.critic_target.modules())  # target networks stay in evaluation mode, as in SAC
    assert all(module.training for module in model.policy.modules() if module not in targets)
    assert not any(module.training for module in targets)
    model.policy.set_training_mode(False)
    assert not any(module.training for module in model.policy.modules())
    model.learn(30, reset_num_timesteps=False)
    assert any(not th.equal(norm.running_mean, stat) for norm, stat in zip(batch_norms, stats, strict=True))


@pytest.mark.parametrize("algo", ALGOS)
def test_callbacks_vec_normalize_and_n_envs(algo: type, tmp_path: Path) -> None:
    """Two training envs under VecNormalize, an evaluation env with three, checkpoints."""
    train_env = VecNormalize(make_vec_env("Pendulum-v1", n_envs=2, seed=0))
    eval_env = VecNormalize(make_vec_env("Pendulum-v1", n_envs=3, seed=1), training=False)
    callbacks = [
        EvalCallback(eval_env, eval_freq=20, n_eval_episodes=3, verbose=0),
        CheckpointCallback(save_freq=25, save_path=str(tmp_path), name_prefix="ckpt"),
    ]
    model = algo("MlpPolicy", train_env, **small()).learn(100, callback=callbacks)
    assert model.num_timesteps >= 100
    assert list(tmp_path.glob("ckpt_*.zip"))
    assert isinstance(model.get_vec_normalize_env(), VecNormalize)


def test_designed_exceptions_are_refused_with_their_reason() -> None:
    """What UDPO's design rules out, with the reason named (SAC accepts these)."""
    image_space = spaces.Dict({"observation": spaces.Box(0, 255, (36, 36, 3), np.uint8), "desired_goal": BOX64})
    SAC("MultiInputPolicy", SpaceEnv(image_space), buffer_size=100)
    with pytest.raises(ValueError, match="is an image"):
        UDPO("MultiInputPolicy", SpaceEnv(image_space), buffer_size=100)
    with pytest.raises(ValueError, match="one-step transitions"):
        UDPO("MlpPolicy", "Pendulum-v1", replay_buffer_class=NStepReplayBuffer)
    with pytest.raises(ValueError, match="one-step transitions"):
        UDPO("MlpPolicy", "Pendulum-v1", n_steps=3)
    with pytest.raises(ValueError, match="gSDE"):
        UDPO("MlpPolicy", "Pendulum-v1", use_sde=True)
    # SAC writes use_sde=False into the policy_kwargs it is given: the same dict must still build a UDPO
    policy_kwargs: dict[str, Any] = {"net_arch": [8]}
    SAC("MlpPolicy", "Pendulum-v1", policy_kwargs=policy_kwargs)
    assert policy_kwargs["use_sde"] is False
    UDPO("MlpPolicy", "Pendulum-v1", policy_kwargs=policy_kwargs)


def test_planner_state_of_other_keys() -> None:
    """A Dict without goals: the planner state is every entry, preprocessed (one-hot for discrete), keys sorted."""
    model = UDPO("MultiInputPolicy", SpaceEnv(OBSERVATION_SPACES["dict_other_keys"]), **small())
    assert model.policy.state_planner.state_keys == ("flags", "mode", "position")
    assert model.policy.state_dim == 3 + 2 + 3 and model.policy.goal_slice is None
    obs = {"flags": np.array([[1, 0, 1]]), "mode": np.array([1]), "position": np.array([[0.1, 0.2, 0.3]])}
    state = model.policy.state_planner.planner_state(model.policy.obs_to_tensor(obs)[0])
    np.testing.assert_allclose(state.numpy(), [[1, 0, 1, 0, 1, 0.1, 0.2, 0.3]], rtol=1e-6)
    assert issubclass(MultiInputPolicy, UDPOPolicy)


def test_vec_normalize_dummy_vec_env_goal_env() -> None:
    """HER under VecNormalize with several envs, as the RL Zoo runs FetchReach."""
    from goal_envs import PointGoalEnv

    for algo in ALGOS:
        env = VecNormalize(DummyVecEnv([PointGoalEnv, PointGoalEnv]), norm_reward=False)
        model = algo("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, **small()).learn(80)
        assert model.replay_buffer.size() > 0
