"""
``LeanSAC(..., cuda_graphs=True)`` (:mod:`sb3_pilot.common.cuda_graph`). On CPU: the switch warns and the eager step
runs; the step on static input tensors gives the eager step's parameters; fallbacks, a changed batch size, reloads and
the losses' device sums. On CUDA (skipped without it): one captured step and one eager step from the same weights and
the same batch give the same parameters to 1e-5, with the batch copied in or drawn inside the graph.
"""

import copy
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.logger import configure

from sb3_pilot.common.cuda_graph import WARMUP_STEPS, CudaGraphUpdate, LossAccumulator, capture_fallback_reason
from sb3_pilot.common.torch_layers import PixelGoalSACPolicy
from sb3_pilot.envs import register_envs
from sb3_pilot.sac import LeanSAC
from tests.goal_envs import PointGoalEnv
from tests.image_envs import ImageGoalEnv

register_envs()
needs_cuda = pytest.mark.skipif(not th.cuda.is_available(), reason="CUDA graphs need a CUDA device")


def make(policy="MultiInputPolicy", env=None, device="cpu", storage="host", **kwargs) -> LeanSAC:
    return LeanSAC(
        policy,
        env if env is not None else PointGoalEnv(),
        learning_starts=50,
        batch_size=16,
        buffer_size=2000,
        policy_kwargs={"net_arch": [32, 32]},
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"storage": storage},
        seed=0,
        device=device,
        **kwargs,
    )


def twin_of(model: LeanSAC, env: gym.Env, **kwargs) -> LeanSAC:
    """A model with ``model``'s weights, temperature, optimizer state and replay buffer."""
    twin = make(model.policy_class, env, device=model.device, **kwargs)
    twin.set_parameters(copy.deepcopy(model.get_parameters()))
    with th.no_grad():
        twin.log_ent_coef.copy_(model.log_ent_coef)
    twin.replay_buffer = model.replay_buffer
    twin._current_progress_remaining = model._current_progress_remaining
    twin.set_logger(configure(None, []))
    return twin


def assert_same_parameters(first: LeanSAC, second: LeanSAC, tolerance: float) -> None:
    reference = second.policy.state_dict()
    for name, value in first.policy.state_dict().items():
        th.testing.assert_close(value, reference[name], rtol=tolerance, atol=tolerance, msg=name)
    th.testing.assert_close(first.log_ent_coef, second.log_ent_coef, rtol=tolerance, atol=tolerance)


def fixed_batch(model: LeanSAC, batch_size: int):
    """Make the buffer return clones of one batch."""
    batch = model.replay_buffer.sample(batch_size, env=model._vec_normalize_env)
    model.replay_buffer.sample = lambda *args, **kwargs: copy.deepcopy(batch)  # type: ignore[method-assign]


def test_cuda_graphs_on_cpu_warns_and_runs_eager() -> None:
    with pytest.warns(UserWarning, match="not a CUDA device, so the eager gradient step is used"):
        model = make(cuda_graphs=True)
    assert model._cuda_graph_update is None and model.cuda_graphs
    model.learn(80)
    assert model._n_updates > 0


@pytest.mark.parametrize(
    "policy, storage, env", [("MultiInputPolicy", "host", PointGoalEnv), ("MultiInputPolicy", "device", PointGoalEnv),
                             (PixelGoalSACPolicy, "device", ImageGoalEnv)]
)  # fmt: skip
def test_static_step_is_the_eager_step(policy, storage: str, env) -> None:
    """The step on static input tensors (what a graph captures) gives the eager step's parameters and losses."""
    eager = make(policy, env(), storage=storage)
    eager.learn(80)
    eager.set_logger(configure(None, []))
    static = twin_of(eager, env())
    update = static._cuda_graph_update = CudaGraphUpdate(static, static._optimizers())
    for model in (eager, static):
        np.random.seed(1)
        th.manual_seed(1)
        model.train(gradient_steps=3, batch_size=16)
    assert_same_parameters(eager, static, 1e-5)
    assert static.actor.optimizer.param_groups[0]["lr"].item() == pytest.approx(3e-4)
    update.losses.record(static.logger)
    for key in ("train/actor_loss", "train/critic_loss", "train/ent_coef", "train/ent_coef_loss"):
        assert static.logger.name_to_value[key] == pytest.approx(eager.logger.name_to_value[key], rel=1e-5), key


def test_fallback_reasons() -> None:
    cuda = th.device("cuda")
    adam = [th.optim.Adam([th.zeros(1, requires_grad=True)])]
    assert capture_fallback_reason(SimpleNamespace(device=cuda, use_sde=False, replay_buffer_class=None), adam) is None
    assert "gSDE" in capture_fallback_reason(SimpleNamespace(device=cuda, use_sde=True, replay_buffer_class=None), adam)
    from stable_baselines3.common.buffers import NStepReplayBuffer

    model = SimpleNamespace(device=cuda, use_sde=False, replay_buffer_class=NStepReplayBuffer)
    assert "n-step" in capture_fallback_reason(model, adam)
    sgd = [th.optim.SGD([th.zeros(1, requires_grad=True)], lr=0.1)]
    assert "SGD has no capturable mode" in capture_fallback_reason(
        SimpleNamespace(device=cuda, use_sde=False, replay_buffer_class=None), sgd
    )
    assert "not a CUDA device" in capture_fallback_reason(SimpleNamespace(device=th.device("cpu")), adam)


def test_batch_size_change_detected_and_reloads_start_over() -> None:
    model = make()
    model.learn(80)
    update = model._cuda_graph_update = CudaGraphUpdate(model, model._optimizers())
    model.train(2, batch_size=16)
    with pytest.warns(UserWarning, match="batch size changed from 16 to 8"):
        model.train(1, batch_size=8)
    assert update._batch is not None and len(update._batch.actions) == 8
    model.set_parameters(model.get_parameters())
    assert update._batch is None and update._warmup_left == WARMUP_STEPS
    model.train(1, batch_size=8)

    # a model saved from captured steps (capturable optimizers) trains eagerly when loaded on CPU
    params = model.get_parameters()
    for name in ("actor.optimizer", "critic.optimizer"):
        for group in params[name]["param_groups"]:
            group["capturable"] = True
    fresh = make()
    fresh.learn(60)
    fresh.set_parameters(params)
    assert not any(group["capturable"] for group in fresh.critic.optimizer.param_groups)
    fresh.learn(20, reset_num_timesteps=False)


def test_loss_accumulator_means_since_last_record() -> None:
    losses = LossAccumulator()
    logger = configure(None, [])
    for step in range(4):
        losses.add("critic_loss", th.tensor(float(step)))
        losses.add("ent_coef", th.tensor([2.0]))
        losses.n_steps += 1
    losses.record(logger)
    assert logger.name_to_value["train/critic_loss"] == 1.5 and logger.name_to_value["train/ent_coef"] == 2.0
    losses.add("critic_loss", th.tensor(5.0))
    losses.add("ent_coef", th.tensor([1.0]))
    losses.n_steps += 1
    losses.record(logger)
    assert logger.name_to_value["train/critic_loss"] == 5.0 and losses.n_steps == 0


@needs_cuda
@pytest.mark.parametrize("policy, env", [("MultiInputPolicy", PointGoalEnv), (PixelGoalSACPolicy, ImageGoalEnv)])
def test_captured_step_is_the_eager_step(policy, env) -> None:
    """From the same weights, batch and seeds: warm-up steps, then captured ones, each gives the eager parameters."""
    eager = make(policy, env(), device="cuda")
    eager.learn(150)
    eager.set_logger(configure(None, []))
    fixed_batch(eager, 16)
    captured = twin_of(eager, env(), cuda_graphs=True)
    update = captured._cuda_graph_update
    assert update is not None
    for step in range(WARMUP_STEPS + 3):
        for model in (eager, captured):
            th.manual_seed(step)
            model.train(gradient_steps=1, batch_size=16)
        assert_same_parameters(eager, captured, 1e-5)
    assert update._graph is not None, "the last steps were replayed graphs"
    update.losses.record(captured.logger)
    assert np.isfinite(captured.logger.name_to_value["train/critic_loss"])


@needs_cuda
def test_draw_in_graph_is_the_eager_draw() -> None:
    """A device-resident buffer with a reward twin: the HER draw is captured too, and gives the eager draw's batch."""
    eager = make(env=gym.make("Pilot/Maze2D-v0"), device="cuda", storage="device")
    eager.learn(200)
    eager.set_logger(configure(None, []))
    assert eager.replay_buffer.draws_in_graph
    captured = twin_of(eager, gym.make("Pilot/Maze2D-v0"), cuda_graphs=True)
    for step in range(WARMUP_STEPS + 3):
        for model in (eager, captured):
            th.manual_seed(step)
            model.train(gradient_steps=1, batch_size=16)
        assert_same_parameters(eager, captured, 1e-5)
    assert captured._cuda_graph_update._key[0] == "draw"
    captured.learn(100, reset_num_timesteps=False)  # and it trains on, adding to the buffer between replays


@needs_cuda
def test_cuda_graphs_learn_save_load(tmp_path) -> None:
    model = make(PixelGoalSACPolicy, ImageGoalEnv(), device="cuda", storage="device", cuda_graphs=True)
    model.learn(120, log_interval=1)
    assert model._cuda_graph_update._graph is not None
    with pytest.warns(UserWarning, match="batch size changed"):
        model.train(1, batch_size=8)
    model.save(tmp_path / "model.zip")
    model.save_replay_buffer(tmp_path / "buffer.pkl")
    on_cpu = LeanSAC.load(tmp_path / "model.zip", env=ImageGoalEnv(), device="cpu")  # warns: eager on CPU
    on_cpu.load_replay_buffer(tmp_path / "buffer.pkl")
    on_cpu.learn(30, reset_num_timesteps=False)
    again = LeanSAC.load(tmp_path / "model.zip", env=ImageGoalEnv(), device="cuda")
    assert again._cuda_graph_update is not None
    again.load_replay_buffer(tmp_path / "buffer.pkl")
    again.learn(30, reset_num_timesteps=False)
