"""
``LeanSAC(..., cuda_graphs=True)`` and ``UDPO(..., cuda_graphs=True)`` (:mod:`sb3_pilot.common.cuda_graph`). On CPU:
the switch warns and the eager step runs (UDPO: the same numbers as without it); the step on static input tensors gives
the eager step's parameters (UDPO: with refits of ``I`` between steps); fallbacks, a changed batch size, reloads and the
losses' device sums. On CUDA (skipped without it): one captured step and one eager step from the same weights and the
same batch give the same parameters to 1e-5, with the batch copied in or drawn inside the graph.
"""

import copy
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.logger import configure

from sb3_pilot import UDPO
from sb3_pilot.common.cuda_graph import WARMUP_STEPS, CudaGraphUpdate, LossAccumulator, capture_fallback_reason
from sb3_pilot.envs import register_envs
from sb3_pilot.pixels import PixelGoalSACPolicy
from sb3_pilot.sac import LeanSAC
from tests.goal_envs import PointGoalEnv
from tests.image_envs import ImageGoalEnv

register_envs()
needs_cuda = pytest.mark.skipif(not th.cuda.is_available(), reason="CUDA graphs need a CUDA device")
#: UDPO's settings here: a refit of I every other gradient step, so that refits fall between captured steps
UDPO_KWARGS = dict(inverse_dynamics_interval=2, inverse_dynamics_gradient_steps=1)


def make(policy="MultiInputPolicy", env=None, device="cpu", storage="host", algo=LeanSAC, **kwargs) -> LeanSAC | UDPO:
    settings = dict(learning_starts=50, batch_size=16, buffer_size=2000, policy_kwargs={"net_arch": [32, 32]})
    if algo is UDPO:
        settings.update(UDPO_KWARGS)
    return algo(
        policy,
        env if env is not None else PointGoalEnv(),
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"storage": storage},
        seed=0,
        device=device,
        **{**settings, **kwargs},
    )


def twin_of(model: LeanSAC | UDPO, env: gym.Env, **kwargs) -> LeanSAC | UDPO:
    """A model with ``model``'s weights, temperature, optimizer state, settings and replay buffer."""
    twin = make(model.policy_class, env, device=model.device, algo=type(model), **kwargs)
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


def test_udpo_cuda_graphs_on_cpu_warns_and_gives_the_eager_numbers(tmp_path) -> None:
    """On CPU, UDPO's switch warns and changes no number (refits of I, target updates and all); it is saved."""
    plain = make(algo=UDPO).learn(80)  # each model made then trained: SB3 seeds the global generators when making one
    with pytest.warns(UserWarning, match="not a CUDA device, so the eager gradient step is used"):
        switched = make(algo=UDPO, cuda_graphs=True)
    assert switched._cuda_graph_update is None and switched.cuda_graphs and not plain.cuda_graphs
    switched.learn(80)
    assert plain._n_updates == switched._n_updates > UDPO_KWARGS["inverse_dynamics_interval"]
    reference = plain.policy.state_dict()
    for name, value in switched.policy.state_dict().items():
        assert th.equal(value, reference[name]), name
    assert th.equal(switched.log_ent_coef, plain.log_ent_coef)

    switched.save(tmp_path / "udpo.zip")
    with pytest.warns(UserWarning, match="not a CUDA device"):
        loaded = UDPO.load(tmp_path / "udpo.zip", env=PointGoalEnv(), device="cpu")
    assert loaded.cuda_graphs and loaded._cuda_graph_update is None
    assert not UDPO.load(tmp_path / "udpo.zip", env=PointGoalEnv(), cuda_graphs=False).cuda_graphs


@pytest.mark.parametrize(
    "algo, policy, storage, env", [(LeanSAC, "MultiInputPolicy", "host", PointGoalEnv),
                                   (LeanSAC, "MultiInputPolicy", "device", PointGoalEnv),
                                   (LeanSAC, PixelGoalSACPolicy, "device", ImageGoalEnv),
                                   (UDPO, "MultiInputPolicy", "host", PointGoalEnv),
                                   (UDPO, "MultiInputPolicy", "device", PointGoalEnv)]
)  # fmt: skip
def test_static_step_is_the_eager_step(algo, policy, storage: str, env) -> None:
    """
    The step on static input tensors (what a graph captures) gives the eager step's parameters and losses; UDPO's
    refits of I run between the steps (``before_step``), as in its eager loop.
    """
    eager = make(policy, env(), storage=storage, algo=algo)
    eager.learn(80)
    eager.set_logger(configure(None, []))
    static = twin_of(eager, env())
    update = static._cuda_graph_update = CudaGraphUpdate(static, static._optimizers())
    for model in (eager, static):
        np.random.seed(1)
        th.manual_seed(1)
        model.train(gradient_steps=3, batch_size=16)
    assert_same_parameters(eager, static, 1e-5)
    assert static._optimizers()[0].param_groups[0]["lr"].item() == pytest.approx(3e-4)
    update.losses.record(static.logger)
    keys = ["train/actor_loss", "train/critic_loss", "train/ent_coef", "train/ent_coef_loss"]
    if algo is UDPO:  # I was refitted in these steps (its parameters are compared too)
        keys += ["train/planner_nll", "train/planner_loss", "train/inverse_dynamics_loss"]
        assert all(key in model.logger.name_to_value for key in keys for model in (eager, static))
    for key in keys:
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
    # an algorithm's own reason (UDPO's linearised entropy term), after the device's
    on_cuda = SimpleNamespace(device=cuda, use_sde=False, replay_buffer_class=None)
    assert capture_fallback_reason(on_cuda, adam, "its own reason") == "its own reason"
    assert "not a CUDA device" in capture_fallback_reason(SimpleNamespace(device=th.device("cpu")), adam, "its own")
    assert make(algo=UDPO)._capture_fallback_reason() is None
    linearised = make(algo=UDPO, entropy_term="linearised")._capture_fallback_reason()
    assert "entropy_term='linearised'" in linearised and "host" in linearised


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


def test_udpo_reloads_start_over_and_a_frozen_planner_skips_the_step() -> None:
    """UDPO's update captures anew after ``set_parameters``, loads capturable optimizers on CPU, and a frozen ``h``
    only refits ``I`` (the critics and the temperature, which exist to train ``h``, are left as they are)."""
    model = make(algo=UDPO).learn(60)
    update = model._cuda_graph_update = CudaGraphUpdate(model, model._optimizers())
    model.train(2, batch_size=16)
    assert update._batch is not None and update.losses.n_steps == 2
    params = model.get_parameters()
    model.set_parameters(params)
    assert update._batch is None and update._warmup_left == WARMUP_STEPS
    for name in ("critic.optimizer", "state_planner.optimizer"):
        for group in params[name]["param_groups"]:
            group["capturable"] = True
    model.set_parameters(params)
    assert not any(group["capturable"] for group in model.state_planner.optimizer.param_groups)
    model.learn(20, reset_num_timesteps=False)

    frozen = make(algo=UDPO, policy_kwargs={"net_arch": [32, 32], "freeze_state_planner": True}).learn(60)
    update = frozen._cuda_graph_update = CudaGraphUpdate(frozen, frozen._optimizers())
    critic, inverse_dynamics = (copy.deepcopy(module.state_dict()) for module in (frozen.critic, frozen.inverse_dynamics))
    frozen.train(2, batch_size=16)  # one refit of I (every other step)
    assert update._batch is None and update.losses.n_steps == 0
    assert all(th.equal(value, frozen.critic.state_dict()[name]) for name, value in critic.items())
    assert not all(th.equal(value, frozen.inverse_dynamics.state_dict()[name]) for name, value in inverse_dynamics.items())


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


def maze() -> gym.Env:
    """A Pilot task whose rewards have a device twin (the HER draw can be captured)."""
    return gym.make("Pilot/Maze2D-v0")


def train_side_by_side(eager: LeanSAC | UDPO, captured: LeanSAC | UDPO) -> None:
    """Warm-up steps, then captured ones, one per ``train()`` from the same seed: the parameters compared after each."""
    for step in range(WARMUP_STEPS + 3):
        for model in (eager, captured):
            th.manual_seed(step)
            model.train(gradient_steps=1, batch_size=16)
        assert_same_parameters(eager, captured, 1e-5)
    assert captured._cuda_graph_update._graph is not None, "the last steps were replayed graphs"


@needs_cuda
@pytest.mark.parametrize(
    "algo, policy, env", [(LeanSAC, "MultiInputPolicy", PointGoalEnv), (LeanSAC, PixelGoalSACPolicy, ImageGoalEnv),
                          (UDPO, "MultiInputPolicy", PointGoalEnv)]
)  # fmt: skip
def test_captured_step_is_the_eager_step(algo, policy, env) -> None:
    """From the same weights, batch and seeds, each step gives the eager parameters (UDPO: I refitted between them)."""
    eager = make(policy, env(), device="cuda", algo=algo)
    eager.learn(150)
    eager.set_logger(configure(None, []))
    fixed_batch(eager, 16)
    captured = twin_of(eager, env(), cuda_graphs=True)
    train_side_by_side(eager, captured)
    captured._cuda_graph_update.losses.record(captured.logger)
    assert np.isfinite(captured.logger.name_to_value["train/critic_loss"])


@needs_cuda
@pytest.mark.parametrize("algo", [LeanSAC, UDPO])
def test_draw_in_graph_is_the_eager_draw(algo) -> None:
    """A device-resident buffer with a reward twin: the HER draw is captured too, and gives the eager draw's batch."""
    eager = make(env=maze(), device="cuda", storage="device", algo=algo)
    eager.learn(200)
    eager.set_logger(configure(None, []))
    assert eager.replay_buffer.draws_in_graph
    captured = twin_of(eager, maze(), cuda_graphs=True)
    train_side_by_side(eager, captured)
    assert captured._cuda_graph_update._key[0] == "draw"
    captured.learn(100, reset_num_timesteps=False)  # and it trains on, adding to the buffer between replays


@needs_cuda
@pytest.mark.parametrize("algo, policy, env", [(LeanSAC, PixelGoalSACPolicy, ImageGoalEnv), (UDPO, "MultiInputPolicy", maze)])
def test_cuda_graphs_learn_save_load(algo, policy, env, tmp_path) -> None:
    model = make(policy, env(), device="cuda", storage="device", algo=algo, cuda_graphs=True)
    model.learn(150, log_interval=1)
    assert model._cuda_graph_update._graph is not None
    with pytest.warns(UserWarning, match="batch size changed"):
        model.train(1, batch_size=8)
    model.save(tmp_path / "model.zip")
    model.save_replay_buffer(tmp_path / "buffer.pkl")
    with pytest.warns(UserWarning, match="not a CUDA device"):
        on_cpu = algo.load(tmp_path / "model.zip", env=env(), device="cpu")
    on_cpu.load_replay_buffer(tmp_path / "buffer.pkl")
    on_cpu.learn(30, reset_num_timesteps=False)
    again = algo.load(tmp_path / "model.zip", env=env(), device="cuda")
    assert again._cuda_graph_update is not None
    again.load_replay_buffer(tmp_path / "buffer.pkl")
    again.learn(30, reset_num_timesteps=False)
