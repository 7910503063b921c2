"""
The lean update (:mod:`sb3_pilot.common.lean`): the ensemble critic computes SB3's critics, a ``LeanSAC`` gradient
step gives SB3's ``SAC`` numbers from the same weights, batch and random draws, and models saved with SB3's twin
critics (SB3's SAC, UDPO of sb3-pilot <= 0.2) load and resume; HER batches are SB3's.
"""

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pandas
import pytest
import torch as th
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.logger import configure
from stable_baselines3.common.policies import ContinuousCritic
from stable_baselines3.common.torch_layers import FlattenExtractor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from benchmarks.temperature_runaway import entropy as recovered_entropy
from sb3_pilot.common.buffers import LeanHerReplayBuffer
from sb3_pilot.common.critics import EnsembleCritic
from sb3_pilot.common.lean import LossRecorder
from sb3_pilot.sac import LeanSAC
from sb3_pilot.udpo import UDPO
from tests.goal_envs import PointGoalEnv

HER = {"replay_buffer_class": HerReplayBuffer, "replay_buffer_kwargs": {"n_sampled_goal": 4}}


def small(**overrides):
    return {"learning_starts": 100, "batch_size": 32, "policy_kwargs": {"net_arch": [32, 32]}, "seed": 0, **overrides}


def test_ensemble_critic_computes_sb3_critics() -> None:
    env = PointGoalEnv()
    space = env.observation_space["observation"]
    kwargs = dict(
        observation_space=space,
        action_space=env.action_space,
        net_arch=[16, 8],
        features_extractor=FlattenExtractor(space),
        features_dim=4,
        n_critics=3,
    )
    sb3_critic, ensemble = ContinuousCritic(**kwargs), EnsembleCritic(**kwargs)
    # nn.Linear's initialisation law: uniform in +-1/sqrt(fan_in), weights and biases
    first = ensemble.q_networks[0]
    bound = 1 / np.sqrt(6)
    assert first.weight.abs().max() <= bound and first.bias.abs().max() <= bound
    assert first.weight.detach().std().item() == pytest.approx(bound / np.sqrt(3), rel=0.2)
    ensemble.load_state_dict(sb3_critic.state_dict())  # stacked on load
    obs, actions = th.randn(5, 4), th.rand(5, 2) * 2 - 1
    expected = th.stack(sb3_critic(obs, actions))
    th.testing.assert_close(ensemble.q_values(obs, actions), expected)
    th.testing.assert_close(th.stack(ensemble(obs, actions)), expected)
    th.testing.assert_close(ensemble.q1_forward(obs, actions), expected[0])


@pytest.mark.parametrize("her", [False, True])
def test_lean_sac_step_equals_sb3_sac_step(her: bool) -> None:
    """From the same weights, buffer and seeds, three gradient steps of each: same losses, same new weights."""
    sac = SAC("MultiInputPolicy", PointGoalEnv(), **small(**(HER if her else {})))
    sac.learn(300)
    lean = LeanSAC("MultiInputPolicy", PointGoalEnv(), **small(**(HER if her else {})))
    lean.set_parameters(copy.deepcopy(sac.get_parameters()))  # SB3's twin critics and their Adam moments, stacked
    with th.no_grad():
        lean.log_ent_coef.copy_(sac.log_ent_coef)  # a saved variable, not among the parameters' state dicts
    lean.replay_buffer = sac.replay_buffer
    lean._n_updates, lean._current_progress_remaining = sac._n_updates, sac._current_progress_remaining
    lean.set_logger(configure(None, []))

    sample = sac.replay_buffer.sample
    for model in (sac, lean):
        th.manual_seed(1)
        model.replay_buffer.sample = _seeded(sample)  # the same batches for both
        model.train(gradient_steps=3, batch_size=32)
    sac_values, lean_values = sac.logger.name_to_value, lean.logger.name_to_value
    for key in ("train/actor_loss", "train/critic_loss", "train/ent_coef", "train/ent_coef_loss"):
        assert lean_values[key] == pytest.approx(sac_values[key], rel=1e-4, abs=1e-6), key

    reference = lean.policy.state_dict()
    converted = copy.deepcopy(sac.get_parameters())
    lean.set_parameters(converted)
    for name, value in lean.policy.state_dict().items():
        th.testing.assert_close(value, reference[name], rtol=1e-4, atol=1e-6, msg=name)


def _seeded(sample):
    """The buffer's sampling with numpy's global generator reset, so both algorithms draw the same batches."""
    calls = iter(range(100))

    def sample_seeded(*args, **kwargs):
        np.random.seed(100 + next(calls))
        return sample(*args, **kwargs)

    return sample_seeded


def test_models_saved_with_sb3_critics_load_and_resume(tmp_path: Path) -> None:
    """An SB3 SAC zip loads into LeanSAC; a UDPO saved with SB3's critic layout (sb3-pilot <= 0.2) loads into UDPO."""
    sac = SAC("MultiInputPolicy", PointGoalEnv(), **small(**HER))
    sac.learn(150)
    sac.save(tmp_path / "sac.zip")
    lean = LeanSAC.load(tmp_path / "sac.zip", env=PointGoalEnv())
    obs = {key: value[None] for key, value in PointGoalEnv().reset(seed=0)[0].items()}
    np.testing.assert_allclose(lean.predict(obs, deterministic=True)[0], sac.predict(obs, deterministic=True)[0], rtol=1e-6)
    q_sac = th.stack(sac.critic(*_batch(sac, obs)))
    th.testing.assert_close(lean.critic.q_values(*_batch(lean, obs)), q_sac)
    assert lean.critic.optimizer.state_dict()["state"], "Adam's moments were carried"
    lean.learn(150)  # and trains on (with the stacked Adam moments)

    udpo = UDPO("MultiInputPolicy", PointGoalEnv(), **small(**HER))
    udpo.learn(150)
    params = udpo.get_parameters()
    q_udpo = udpo.critic.q_values(*_batch(udpo, obs))
    old = _as_sb3_critics(params, udpo.critic.n_critics)
    reloaded = UDPO("MultiInputPolicy", PointGoalEnv(), **small(**HER))
    reloaded.set_parameters(old)
    th.testing.assert_close(reloaded.critic.q_values(*_batch(reloaded, obs)), q_udpo)


def _batch(model, obs):
    obs_tensor, _ = model.policy.obs_to_tensor(obs)
    return obs_tensor, th.zeros(1, 2)


def _as_sb3_critics(params: dict, n_critics: int) -> dict:
    """The parameters in SB3's critic layout (``qf{i}.{layer}``), as sb3-pilot <= 0.2 saved UDPO."""
    params = copy.deepcopy(params)
    policy = params["policy"]
    for prefix in ("critic.", "critic_target."):
        for key in [key for key in policy if key.startswith(f"{prefix}q_networks.")]:
            layer, kind = key[len(f"{prefix}q_networks.") :].split(".")
            value = policy.pop(key)
            for idx in range(n_critics):
                policy[f"{prefix}qf{idx}.{layer}.{kind}"] = value[idx].T if kind == "weight" else value[idx, 0]
    params["critic.optimizer"]["state"] = {}
    n_params = sum(key.startswith("critic.qf") for key in policy)
    params["critic.optimizer"]["param_groups"][0]["params"] = list(range(n_params))
    return params


@pytest.mark.parametrize("copy_info_dict, buffer_size", [(False, 1_000_000), (True, 1_000_000), (False, 200)])
def test_lean_her_samples_are_sb3_her_samples(copy_info_dict: bool, buffer_size: int) -> None:
    """
    Same stored transitions, same random state: the same batch as SB3's HerReplayBuffer, VecNormalize included, in a
    buffer still filling (the lean one scans only its written rows) and in a full one that wrapped round.
    """
    env = VecNormalize(DummyVecEnv([PointGoalEnv, PointGoalEnv]))
    her = {**HER, "replay_buffer_kwargs": {"n_sampled_goal": 4, "copy_info_dict": copy_info_dict}}
    sac = SAC("MultiInputPolicy", env, **small(**her), buffer_size=buffer_size)
    assert type(sac.replay_buffer) is HerReplayBuffer
    sac.learn(300)
    assert sac.replay_buffer.full == (buffer_size == 200)
    lean = copy.copy(sac.replay_buffer)
    lean.__class__ = LeanHerReplayBuffer
    lean.set_env(sac.replay_buffer.env)  # not copied: HerReplayBuffer.__getstate__ drops it
    samples = []
    for buffer in (sac.replay_buffer, lean):
        np.random.seed(3)
        samples.append(buffer.sample(64, env=env))
    for name, expected in samples[0]._asdict().items():
        actual = samples[1]._asdict()[name]
        if isinstance(expected, dict):
            for key in expected:
                th.testing.assert_close(actual[key], expected[key], msg=f"{name}[{key}]")
        elif expected is not None:
            th.testing.assert_close(actual, expected, msg=name)
    assert LeanSAC("MultiInputPolicy", PointGoalEnv(), **small(**HER)).replay_buffer_class is LeanHerReplayBuffer


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"buffer_size": 0}, "buffer_size must be >= 1"),
        ({"buffer_size": -10}, "buffer_size must be >= 1"),
        ({"batch_size": 0}, "batch_size must be >= 1"),
        ({"batch_size": -3}, "batch_size must be >= 1"),
        ({"tau": 1.5}, "tau must be <= 1"),
        ({"gamma": -0.5}, "gamma must be >= 0"),
    ],
)
def test_lean_sac_refuses_empty_buffers_batches_and_bad_coefficients(kwargs: dict, message: str) -> None:
    """SB3 accepts buffer_size=0, fails on batch_size=0 at its first sample, trains on tau=1.5: LeanSAC refuses them."""
    with pytest.raises(ValueError, match=message):
        LeanSAC("MultiInputPolicy", PointGoalEnv(), **kwargs)


class HugeRewardGoalEnv(PointGoalEnv):
    """PointGoalEnv with rewards of -1e30: the critics' squared errors overflow float32 at the first gradient step."""

    def compute_reward(self, achieved_goal: np.ndarray, desired_goal: np.ndarray, info: Any) -> np.ndarray:
        return super().compute_reward(achieved_goal, desired_goal, info) * 1e30


@pytest.mark.parametrize("algo", [LeanSAC, UDPO])
def test_an_overflowing_loss_stops_training_at_once(algo: type[LeanSAC] | type[UDPO]) -> None:
    """An infinite critic loss ends ``learn`` at the next record with the losses named, not NaN parameters later."""
    model = algo("MultiInputPolicy", HugeRewardGoalEnv(), learning_starts=20, batch_size=16, seed=0)
    with pytest.raises(FloatingPointError, match=r"Training diverged: train/critic_loss .* not finite \(.*ent_coef="):
        model.learn(40)


def test_loss_recorder_refuses_a_non_finite_mean() -> None:
    """Every loss recorded when all are finite; NaN or inf named, and nothing recorded."""
    logger = configure(None, [])
    recorder = LossRecorder()
    recorder.add("critic_loss", th.tensor(1.0))
    recorder.add("actor_loss", th.tensor(-2.0))
    recorder.record(logger)
    assert logger.name_to_value == {"train/critic_loss": 1.0, "train/actor_loss": -2.0}
    logger.dump()
    recorder.add("ent_coef", th.tensor(float("nan")))
    with pytest.raises(FloatingPointError, match=r"train/ent_coef over the last gradient steps is not finite"):
        recorder.record(logger)
    assert logger.name_to_value == {}


@pytest.mark.parametrize("algo", [LeanSAC, UDPO])
def test_the_policy_entropy_estimate_is_logged(algo: type[LeanSAC] | type[UDPO]) -> None:
    """``train/entropy`` is the ``-mean log pi`` the temperature's loss reads: loss = -log(alpha) (target - entropy)."""
    model = algo("MultiInputPolicy", PointGoalEnv(), learning_starts=50, batch_size=16, seed=0)
    model.learn(60)
    model.set_logger(configure(None, []))
    model.train(gradient_steps=1, batch_size=16)
    values = model.logger.name_to_value
    expected = -np.log(values["train/ent_coef"]) * (model.target_entropy - values["train/entropy"])
    assert values["train/ent_coef_loss"] == pytest.approx(expected, rel=1e-4, abs=1e-6)


def test_the_entropy_is_recovered_from_older_logs() -> None:
    """``benchmarks.temperature_runaway`` reads ``-mean log pi`` back from the temperature's loss where no
    ``train/entropy`` was logged (undefined at a temperature of 1)."""
    alpha, entropy = np.array([0.5, 2.0, 1.0]), np.array([0.3, -0.7, 0.1])
    frame = pandas.DataFrame({"train/ent_coef": alpha, "train/ent_coef_loss": -np.log(alpha) * (-1.0 - entropy)})
    recovered = recovered_entropy(frame, target_entropy=-1.0).to_numpy()
    np.testing.assert_allclose(recovered[:2], entropy[:2])
    assert np.isnan(recovered[2])
    assert recovered_entropy(frame.assign(**{"train/entropy": entropy}), -1.0).tolist() == entropy.tolist()
