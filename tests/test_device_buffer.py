"""
The device-resident storage of :class:`~sb3_pilot.common.buffers.LeanHerReplayBuffer` (``storage="device"``), tested
against SB3's ``HerReplayBuffer`` on CPU (and on CUDA where there is one): the same episodes stored, SB3's relabelling
semantics, uniform draws, rewards equal to ``compute_reward`` (by its torch twin for the package's tasks, exact at the
threshold), ``VecNormalize`` at sampling time, timeouts, save/load as numpy, the bonus buffer, the memory cap.
"""

import pickle
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.save_util import load_from_pkl, save_to_pkl
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_pilot.common.buffers import MAX_DEVICE_MEMORY_FRACTION, LeanHerReplayBuffer, device_reward_function
from sb3_pilot.envs import register_envs
from sb3_pilot.envs.core import GoalReachingMixin, torch_reward_twin
from sb3_pilot.envs.maze import Maze2DEnv
from sb3_pilot.sac import LeanSAC
from sb3_pilot.transfer import PilotBonusWrapper, PilotHerReplayBuffer
from sb3_pilot.transfer.bonus import PREVIOUS_ACHIEVED_GOAL
from tests.goal_envs import PointGoalEnv
from tests.maze_envs import WallMazeEnv

register_envs()
DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not th.cuda.is_available(), reason="needs CUDA"))]


def make_buffers(venv, buffer_size: int = 200, device: str = "cpu", **kwargs):
    """SB3's HER buffer and the device-resident one, same arguments."""
    common = dict(buffer_size=buffer_size, observation_space=venv.observation_space, action_space=venv.action_space)
    common.update(env=venv, n_envs=venv.num_envs, n_sampled_goal=4, **kwargs)
    return HerReplayBuffer(**common, device="cpu"), LeanHerReplayBuffer(**common, device=device, storage="device")


def fill(venv, buffers, steps: int, seed: int = 0) -> None:
    """Random actions, every transition stored in each buffer as SB3's off-policy loop stores it."""
    rng = np.random.default_rng(seed)
    venv.seed(seed)
    obs = venv.reset()
    for _ in range(steps):
        actions = rng.uniform(-1, 1, (venv.num_envs, 2)).astype(np.float32)
        new_obs, rewards, dones, infos = venv.step(actions)
        next_obs = {key: value.copy() for key, value in new_obs.items()}
        for idx, done in enumerate(dones):
            if done:
                for key in next_obs:
                    next_obs[key][idx] = infos[idx]["terminal_observation"][key]
        for buffer in buffers:
            buffer.add(
                {key: value.copy() for key, value in obs.items()},
                {key: value.copy() for key, value in next_obs.items()},
                actions,
                rewards,
                dones,
                infos,
            )
        obs = new_obs


def host(value):
    return value.cpu().numpy() if isinstance(value, th.Tensor) else value


def assert_same_storage(sb3: HerReplayBuffer, device: LeanHerReplayBuffer) -> None:
    for name in ("observations", "next_observations"):
        for key, values in getattr(sb3, name).items():
            np.testing.assert_array_equal(host(getattr(device, name)[key]), values, err_msg=f"{name}[{key}]")
    for name in ("actions", "rewards", "dones", "timeouts", "ep_start", "ep_length"):
        np.testing.assert_array_equal(host(getattr(device, name)), getattr(sb3, name), err_msg=name)
    np.testing.assert_array_equal(host(device._ep_start_device), sb3.ep_start)
    np.testing.assert_array_equal(host(device._ep_length_device), sb3.ep_length)
    assert (device.pos, device.full) == (sb3.pos, sb3.full)
    assert device._n_valid == np.count_nonzero(sb3.ep_length)


@pytest.mark.parametrize("device", DEVICES)
def test_device_storage_stores_sb3s_episodes(device: str) -> None:
    """Two envs, a buffer that wraps round (old episodes overwritten), and a truncated last trajectory."""
    venv = DummyVecEnv([PointGoalEnv, PointGoalEnv])
    sb3, lean = make_buffers(venv, device=device)
    fill(venv, [sb3, lean], 337)
    assert sb3.full
    assert_same_storage(sb3, lean)
    assert isinstance(lean.observations["observation"], th.Tensor) and lean.observations["observation"].device.type == device
    with pytest.warns(UserWarning, match="truncated"):
        sb3.truncate_last_trajectory()
    with pytest.warns(UserWarning, match="truncated"):
        lean.truncate_last_trajectory()
    assert_same_storage(sb3, lean)


def episode_goals(buffer: HerReplayBuffer, row: int, env: int) -> tuple[np.ndarray, int]:
    """The next achieved goals of the episode of a stored transition, and the transition's index in it."""
    start, length = buffer.ep_start[row, env], buffer.ep_length[row, env]
    rows = (start + np.arange(length)) % buffer.buffer_size
    return buffer.next_observations["achieved_goal"][rows, env], int((row - start) % buffer.buffer_size)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("strategy", ["future", "final", "episode"])
def test_relabelling_is_sb3s(strategy: str, device: str) -> None:
    """
    Real transitions are stored ones; relabelled goals are next achieved goals of the same episode (later ones for
    "future", inclusive; the last for "final"), with the env's compute_reward; statistics match SB3's sampling.
    """
    venv = DummyVecEnv([lambda: gym.make("Pilot/Maze2D-v0"), lambda: gym.make("Pilot/Maze2D-v0")])
    sb3, lean = make_buffers(venv, buffer_size=300, device=device, goal_selection_strategy=strategy)
    fill(venv, [sb3, lean], 420)
    assert lean._device_reward is not None, "Maze2D's reward has a torch twin"
    rows_of_action = {sb3.actions[row, env].tobytes(): (row, env) for row in range(sb3.buffer_size) for env in range(2)}
    th.manual_seed(0)
    batch = lean.sample(512)
    n_virtual = int(lean.her_ratio * 512)
    compute_reward = venv.envs[0].unwrapped.compute_reward
    offsets = []
    for i, action in enumerate(host(batch.actions)):
        row, env = rows_of_action[action.tobytes()]
        assert sb3.ep_length[row, env] > 0, "only transitions of finished episodes are drawn"
        obs = {key: host(value[i]) for key, value in batch.observations.items()}
        next_obs = {key: host(value[i]) for key, value in batch.next_observations.items()}
        np.testing.assert_array_equal(obs["observation"], sb3.observations["observation"][row, env])
        np.testing.assert_array_equal(next_obs["achieved_goal"], sb3.next_observations["achieved_goal"][row, env])
        np.testing.assert_array_equal(obs["desired_goal"], next_obs["desired_goal"])
        reward = host(batch.rewards[i, 0])
        if i < 512 - n_virtual:
            np.testing.assert_array_equal(obs["desired_goal"], sb3.observations["desired_goal"][row, env])
            assert reward == sb3.rewards[row, env]
            continue
        goals, current = episode_goals(sb3, row, env)
        matches = np.flatnonzero((goals == obs["desired_goal"]).all(axis=1))
        assert len(matches), "a relabelled goal comes from the same episode"
        if strategy == "future":
            assert matches.max() >= current
        elif strategy == "final":
            assert matches.max() == len(goals) - 1
        offsets.append((matches.max() - current) / len(goals))
        assert reward == compute_reward(next_obs["achieved_goal"][None], obs["desired_goal"][None], {})[0]
    # the same statistics as SB3's sampling of the same buffer
    np.random.seed(0)
    sb3_batch = sb3.sample(4096)
    lean_batch = lean.sample(4096)
    virtual = slice(4096 - int(lean.her_ratio * 4096), 4096)
    assert host(lean_batch.rewards[virtual]).mean() == pytest.approx(sb3_batch.rewards[virtual].mean().item(), abs=0.05)
    if strategy != "final":
        assert np.std(offsets) > 0.05, "goals spread over the episode"


@pytest.mark.parametrize("device", DEVICES)
def test_draws_are_uniform_over_finished_episodes(device: str) -> None:
    venv = DummyVecEnv([PointGoalEnv, PointGoalEnv])
    _, lean = make_buffers(venv, buffer_size=200, device=device)
    fill(venv, [lean], 160)
    rows_of_action = {host(lean.actions[row, env]).tobytes(): row * 2 + env for row in range(100) for env in range(2)}
    counts = np.zeros(200)
    for _ in range(4):
        batch = lean.sample(10_000)
        for action in host(batch.actions):
            counts[rows_of_action[action.tobytes()]] += 1
    valid = lean.ep_length.reshape(-1) > 0
    assert counts[~valid].sum() == 0, "transitions of unfinished or overwritten episodes are never drawn"
    expected = counts.sum() / valid.sum()
    assert np.abs(counts[valid] - expected).max() < 5 * np.sqrt(expected)


class ThresholdGoals(GoalReachingMixin):
    distance_threshold = 0.05


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("goal_dim", [1, 2, 3, 7])
def test_torch_twin_is_compute_reward_at_the_threshold(goal_dim: int, device: str) -> None:
    """float32 goals at distances within a few ulps of the threshold: the same rewards as numpy's float64 norm."""
    rng = np.random.default_rng(goal_dim)
    env = ThresholdGoals()
    desired = rng.normal(size=(20_000, goal_dim)).astype(np.float32)
    direction = rng.normal(size=(20_000, goal_dim))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    distance = env.distance_threshold * (1 + rng.integers(-8, 9, size=(20_000, 1)) * 1e-7)
    achieved = (desired + direction * distance).astype(np.float32)
    expected = env.compute_reward(achieved, desired, {})
    assert 0.2 < (expected == 0).mean() < 0.8, "both sides of the threshold"
    twin = env.compute_reward_torch(th.as_tensor(achieved, device=device), th.as_tensor(desired, device=device))
    assert twin.dtype == th.float32
    np.testing.assert_array_equal(host(twin), expected)


def test_twin_only_where_compute_reward_is_the_mixins() -> None:
    maze = gym.make("Pilot/Maze2D-v0")
    assert torch_reward_twin(maze, 2) is not None, "through gymnasium's wrappers"
    assert torch_reward_twin(maze, 8) is None, "numpy sums 8 or more terms pairwise"
    assert device_reward_function(VecNormalize(DummyVecEnv([lambda: gym.make("Pilot/Maze2D-v0")])), 2) is not None

    class Shifted(Maze2DEnv):
        def compute_reward(self, achieved_goal, desired_goal, info):
            return super().compute_reward(achieved_goal, desired_goal, info) + 1.0

    class Rewarded(gym.Wrapper):
        def compute_reward(self, achieved_goal, desired_goal, info):
            return self.env.unwrapped.compute_reward(achieved_goal, desired_goal, info) * 2

    assert torch_reward_twin(Shifted(), 2) is None
    assert torch_reward_twin(Rewarded(gym.make("Pilot/Maze2D-v0")), 2) is None
    assert torch_reward_twin(PointGoalEnv(), 2) is None, "not a GoalReachingMixin: compute_reward on CPU copies"


def test_envs_without_twin_and_wrong_twins_use_compute_reward() -> None:
    """A reward wrapper (no twin) and a twin that disagrees with compute_reward: the rewards are compute_reward's."""

    class Doubled(gym.Wrapper):
        def compute_reward(self, achieved_goal, desired_goal, info):
            return self.env.unwrapped.compute_reward(achieved_goal, desired_goal, info) * 2

    venv = DummyVecEnv([lambda: Doubled(gym.make("Pilot/Maze2D-v0"))])
    _, lean = make_buffers(venv)
    assert lean._device_reward is None
    fill(venv, [lean], 120)
    batch = lean.sample(256)
    virtual = slice(256 - int(lean.her_ratio * 256), 256)
    expected = 2 * venv.envs[0].unwrapped.compute_reward(
        host(batch.next_observations["achieved_goal"][virtual]), host(batch.observations["desired_goal"][virtual]), {}
    )
    np.testing.assert_array_equal(host(batch.rewards[virtual, 0]), expected)
    assert (expected == -2).any()

    venv = DummyVecEnv([lambda: gym.make("Pilot/Maze2D-v0")])
    _, lean = make_buffers(venv)
    fill(venv, [lean], 120)
    lean._device_reward = lambda achieved, desired: th.zeros(len(achieved))
    with pytest.warns(UserWarning, match="differs from compute_reward"):
        batch = lean.sample(256)
    assert lean._device_reward is None and not lean.draws_in_graph
    expected = venv.envs[0].unwrapped.compute_reward(
        host(batch.next_observations["achieved_goal"][virtual]), host(batch.observations["desired_goal"][virtual]), {}
    )
    np.testing.assert_array_equal(host(batch.rewards[virtual, 0]), expected)


@pytest.mark.parametrize("handle_timeout_termination", [True, False])
@pytest.mark.parametrize("norm_reward", [False, True])
def test_vecnormalize_and_timeouts_at_sampling_time(norm_reward: bool, handle_timeout_termination: bool) -> None:
    """Normalised as VecNormalize normalises (float64, then float32: bit for bit); time-limit ends are not dones."""
    venv = VecNormalize(DummyVecEnv([PointGoalEnv]), norm_reward=norm_reward, clip_obs=0.5)
    sb3, lean = make_buffers(venv, handle_timeout_termination=handle_timeout_termination)
    fill(venv, [sb3, lean], 150)
    batch = lean.sample(512, env=venv)
    rows_of_action = {sb3.actions[row, 0].tobytes(): row for row in range(150)}
    rows = np.array([rows_of_action[action.tobytes()] for action in host(batch.actions)])
    n_real = 512 - int(lean.her_ratio * 512)
    for name in ("observations", "next_observations"):
        expected = venv.normalize_obs({key: values[rows, 0] for key, values in getattr(sb3, name).items()})
        for key in ("observation", "achieved_goal"):
            np.testing.assert_array_equal(host(getattr(batch, name)[key]), expected[key], err_msg=f"{name}[{key}]")
        np.testing.assert_array_equal(host(getattr(batch, name)["desired_goal"])[:n_real], expected["desired_goal"][:n_real])
    assert (np.abs(host(batch.observations["observation"])) <= 0.5).all() and (
        host(batch.observations["observation"]) == 0.5
    ).any()
    np.testing.assert_array_equal(
        host(batch.rewards[:n_real, 0]), venv.normalize_reward(sb3.rewards[rows[:n_real], 0]).astype(np.float32)
    )
    episode_ends = sb3.dones[rows, 0] == 1
    assert episode_ends.any()
    assert (host(batch.dones[episode_ends, 0]) == (0 if handle_timeout_termination else 1)).all()


def test_saved_as_numpy_and_loaded(tmp_path) -> None:
    """Pickled as numpy arrays (a CUDA buffer loads without CUDA); loaded, it moves to ``device`` when next used."""
    venv = DummyVecEnv([PointGoalEnv, PointGoalEnv])
    sb3, lean = make_buffers(venv)
    fill(venv, [sb3, lean], 90)
    state = lean.__getstate__()
    assert isinstance(state["observations"]["observation"], np.ndarray) and isinstance(state["rewards"], np.ndarray)
    assert not any(isinstance(value, th.Tensor) for value in state.values())
    save_to_pkl(tmp_path / "buffer.pkl", lean)
    loaded = load_from_pkl(tmp_path / "buffer.pkl")
    loaded.set_env(venv)
    assert isinstance(loaded.rewards, th.Tensor) and loaded._device_reward is None
    assert_same_storage(sb3, loaded)
    loaded.device = th.device("cpu")
    fill(venv, [sb3, loaded], 40, seed=1)
    assert_same_storage(sb3, loaded)
    assert loaded.sample(32).rewards.shape == (32, 1)

    # through the model: save_replay_buffer / load_replay_buffer
    model = LeanSAC("MultiInputPolicy", PointGoalEnv(), learning_starts=30, batch_size=16, buffer_size=500, seed=0,
                    policy_kwargs={"net_arch": [8]}, replay_buffer_class=HerReplayBuffer,
                    replay_buffer_kwargs={"storage": "device"})  # fmt: skip
    model.learn(60)
    model.save_replay_buffer(tmp_path / "model_buffer.pkl")
    stored = host(model.replay_buffer.observations["observation"]).copy()
    model.load_replay_buffer(tmp_path / "model_buffer.pkl")
    np.testing.assert_array_equal(host(model.replay_buffer.observations["observation"]), stored)
    model.learn(40, reset_num_timesteps=False)


def test_pilot_bonus_on_device_storage() -> None:
    """PilotHerReplayBuffer's bonus of relabelled goals, read from the stored achieved goals (on host copies)."""
    th.manual_seed(0)
    from sb3_pilot.distill import GoalPlanner

    env = PilotBonusWrapper(WallMazeEnv(), GoalPlanner(2, net_arch=[16], metadata={"source_task": "WallMazeEnv"}), beta=0.5)
    venv = DummyVecEnv([lambda: env])
    buffer = PilotHerReplayBuffer(200, env.observation_space, env.action_space, env=venv, storage="device")
    assert buffer._device_reward is None
    fill(venv, [buffer], 120)
    batch = buffer.sample(256)
    virtual = slice(256 - int(buffer.her_ratio * 256), 256)
    info = {PREVIOUS_ACHIEVED_GOAL: host(batch.observations["achieved_goal"][virtual])}
    expected = env.compute_reward(
        host(batch.next_observations["achieved_goal"][virtual]), host(batch.observations["desired_goal"][virtual]), info
    )
    np.testing.assert_allclose(host(batch.rewards[virtual, 0]), expected, rtol=1e-6)
    assert len(np.unique(expected)) > 10, "the bonus varies with the relabelled goal"
    restored = pickle.loads(pickle.dumps(buffer))
    assert restored.infos.buffer is restored


def test_device_memory_cap_and_bad_storage(monkeypatch) -> None:
    venv = DummyVecEnv([PointGoalEnv])
    _, lean = make_buffers(venv, buffer_size=1000)
    per_transition = lean.storage_nbytes() / 1000
    # observation and next observation (4 + 2 + 2 floats), action, reward / done / timeout, episode start and length
    assert per_transition == 2 * (4 + 2 + 2) * 4 + 2 * 4 + 3 * 4 + 2 * 8
    total = lean.storage_nbytes() / MAX_DEVICE_MEMORY_FRACTION
    monkeypatch.setattr(th.cuda, "get_device_properties", lambda device: SimpleNamespace(total_memory=total - 1))
    with pytest.raises(ValueError, match="choose a smaller buffer_size"):
        lean._check_device_memory(th.device("cuda"))
    monkeypatch.setattr(th.cuda, "get_device_properties", lambda device: SimpleNamespace(total_memory=total))
    lean._check_device_memory(th.device("cuda"))
    with pytest.raises(ValueError, match="storage must be one of"):
        LeanHerReplayBuffer(10, venv.observation_space, venv.action_space, env=venv, storage="disk")


def test_udpo_trains_on_device_storage() -> None:
    """UDPO's steps and its inverse-dynamics refits (one large draw) read the device-resident buffer too."""
    from sb3_pilot import UDPO

    model = UDPO(
        "MultiInputPolicy",
        gym.make("Pilot/Maze2D-v0"),
        buffer_size=1000,
        learning_starts=60,
        batch_size=16,
        inverse_dynamics_interval=20,
        inverse_dynamics_gradient_steps=4,
        policy_kwargs={"net_arch": [16]},
        replay_buffer_class=HerReplayBuffer,
        replay_buffer_kwargs={"storage": "device"},
        seed=0,
        device="cpu",
    )
    assert isinstance(model.replay_buffer, LeanHerReplayBuffer) and model.replay_buffer.storage == "device"
    model.learn(100)
    assert model.replay_buffer._device_reward is not None and model._n_updates == 40


def test_distillation_reads_device_storage() -> None:
    """The distiller's buffer draws (``s ~ B``, ``g_target ~ p_g``) are the same host arrays from either storage."""
    from sb3_pilot.distill.distill import sample_buffer_pairs

    venv = DummyVecEnv([PointGoalEnv, PointGoalEnv])
    sb3, lean = make_buffers(venv)
    fill(venv, [sb3, lean], 150)
    host = sample_buffer_pairs(sb3, 64, np.random.default_rng(0))
    device = sample_buffer_pairs(lean, 64, np.random.default_rng(0))
    for key, value in host.items():
        assert isinstance(device[key], np.ndarray), key
        np.testing.assert_array_equal(device[key], value)
