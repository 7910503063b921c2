"""Any SB3 agent on a goal env as the distillation's teacher: SAC, TD3, TQC (and files of them), and bad teachers."""

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from goal_envs import PointGoalEnv
from gymnasium import spaces
from sb3_contrib import TQC
from stable_baselines3 import DDPG, DQN, SAC, TD3, HerReplayBuffer
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_pilot import GoalPlanner, distill_goal_planner
from sb3_pilot.common.saved_models import without_replay_buffer
from sb3_pilot.distill import load_teacher
from sb3_pilot.distill.distill import rollout_pairs
from sb3_pilot.distill.teacher import DETERMINISTIC_TEACHER_NOISE

#: Small settings: a few hundred env steps, some 50 gradient steps
TEACHER_KWARGS = {
    "replay_buffer_class": HerReplayBuffer,
    "learning_starts": 250,
    "buffer_size": 1000,  # SB3's 1e6 takes seconds to allocate
    "batch_size": 64,
    "policy_kwargs": {"net_arch": [32, 32]},
    "seed": 0,
}
DISTILL_KWARGS = {"n_samples": 1000, "gradient_steps": 50, "batch_size": 64, "net_arch": [16], "support_size": 100}


def teacher_kwargs() -> dict:
    return {**TEACHER_KWARGS, "policy_kwargs": {"net_arch": [32, 32]}}  # a new dict: SAC writes into it


def train(algorithm: type[BaseAlgorithm], env=None) -> BaseAlgorithm:
    return algorithm("MultiInputPolicy", env if env is not None else PointGoalEnv(), **teacher_kwargs()).learn(300)


@pytest.fixture(scope="module")
def teachers() -> dict[str, BaseAlgorithm]:
    return {algorithm.__name__: train(algorithm) for algorithm in (SAC, TD3, TQC)}


@pytest.mark.parametrize("name", ["SAC", "TD3", "TQC"])
def test_sb3_agents_distil_with_rollout_labels(teachers: dict[str, BaseAlgorithm], name: str) -> None:
    """An SB3 agent's real steps are the labels; its algorithm and rollout success are in the planner's metadata."""
    teacher = teachers[name]
    planner = distill_goal_planner(teacher, **DISTILL_KWARGS, env=Monitor(PointGoalEnv()))
    metadata = planner.metadata
    assert metadata["teacher_algorithm"] == name and metadata["labels"] == "rollouts"
    assert metadata["source_task"] == "PointGoalEnv" and 0.0 <= metadata["rollout_success"] <= 1.0
    assert metadata["rollout_noise"] == (DETERMINISTIC_TEACHER_NOISE if name == "TD3" else 0.0)  # deterministic actor
    assert metadata["holdout"]["nll"] < metadata["holdout"]["nll_untrained"]
    support = planner.support.numpy()  # real positions of the rollouts: inside the env's box
    assert len(support) == 100 and np.abs(support).max() <= 1.0
    assert planner.predict(np.zeros(2), np.full(2, 0.5)).shape == (2,)


def test_rollout_noise_spreads_a_deterministic_teacher(teachers: dict[str, BaseAlgorithm]) -> None:
    """TD3 acts deterministically even when asked to sample: the noise on its normalised action gives its rollouts a
    spread, and the labels stay real steps (inside the env's box)."""
    teacher = teachers["TD3"]
    plain = [rollout_pairs(teacher, Monitor(PointGoalEnv()), 100, seed=0).next_goals for _ in range(2)]
    noisy = rollout_pairs(teacher, Monitor(PointGoalEnv()), 100, seed=0, noise=0.3)
    np.testing.assert_array_equal(plain[0], plain[1])  # no spread without the noise
    assert not np.allclose(noisy.next_goals, plain[0]) and np.abs(noisy.next_goals).max() <= 1.0
    deterministic = distill_goal_planner(teacher, **DISTILL_KWARGS, env=PointGoalEnv(), deterministic=True)
    assert deterministic.metadata["rollout_noise"] == 0.0  # asked for deterministic actions: no default noise
    chosen = distill_goal_planner(teacher, **DISTILL_KWARGS, env=PointGoalEnv(), rollout_noise=0.2)
    assert chosen.metadata["rollout_noise"] == 0.2
    with pytest.raises(ValueError, match="rollout_noise must be >= 0"):
        distill_goal_planner(teacher, env=PointGoalEnv(), rollout_noise=-0.1)


def test_planned_labels_refuse_other_agents(teachers: dict[str, BaseAlgorithm]) -> None:
    with pytest.raises(ValueError, match=r"labels='planned' reads UDPO's state planner.*SAC teacher"):
        distill_goal_planner(teachers["SAC"], labels="planned")


def test_a_teacher_that_reaches_no_goal_is_refused_unless_allowed() -> None:
    """With a success radius of 0 no step reaches a goal: an error that says so, unless the caller goes on knowingly."""
    teacher = train(SAC, PointGoalEnv(success_distance=0.0))
    with pytest.raises(ValueError, match=r"reached no goal in 300 steps.*allow_unsuccessful_teacher=True"):
        distill_goal_planner(teacher, **{**DISTILL_KWARGS, "n_samples": 300})
    planner = distill_goal_planner(teacher, **{**DISTILL_KWARGS, "n_samples": 300}, allow_unsuccessful_teacher=True)
    assert planner.metadata["rollout_success"] == 0.0 and planner.metadata["teacher_algorithm"] == "SAC"


def test_teacher_files_load_with_their_algorithm(teachers: dict[str, BaseAlgorithm], tmp_path: Path) -> None:
    """A saved model, with its VecNormalize statistics as an RL-Zoo run keeps them, distils from its path."""
    venv = VecNormalize(DummyVecEnv([lambda: Monitor(PointGoalEnv())]), norm_reward=False)
    model = train(TQC, venv)
    (tmp_path / "run").mkdir()
    model.save(tmp_path / "run" / "PointGoalEnv")
    venv.save(tmp_path / "run" / "vecnormalize.pkl")
    env = VecNormalize.load(str(tmp_path / "run" / "vecnormalize.pkl"), DummyVecEnv([lambda: Monitor(PointGoalEnv())]))
    env.training = False
    planner = distill_goal_planner(tmp_path / "run" / "PointGoalEnv", **DISTILL_KWARGS, env=env)  # ".zip" left out
    assert planner.metadata["teacher_algorithm"] == "TQC"
    assert np.abs(planner.support.numpy()).max() <= 1.0  # raw positions, not normalised ones

    teachers["TD3"].save(tmp_path / "td3.zip")
    assert type(load_teacher(tmp_path / "td3.zip")) is TD3
    DDPG("MultiInputPolicy", PointGoalEnv(), **teacher_kwargs()).save(tmp_path / "ddpg.zip")
    assert type(load_teacher(tmp_path / "ddpg.zip")) is DDPG  # saved with a TD3 policy, told apart by its settings


class DiscretePointEnv(PointGoalEnv):
    """PointGoalEnv with four discrete pushes."""

    def __init__(self) -> None:
        super().__init__()
        self.action_space = spaces.Discrete(4)

    def step(self, action):
        return super().step(np.array([[1, 0], [-1, 0], [0, 1], [0, -1]], dtype=np.float32)[int(action)])


def test_bad_teachers_are_refused_by_name_before_work(teachers: dict[str, BaseAlgorithm], tmp_path: Path) -> None:
    box_teacher = SAC("MlpPolicy", "Pendulum-v1", learning_starts=10, batch_size=8).learn(20)
    with pytest.raises(ValueError, match=r"goal env.*SAC teacher's observation space"):
        distill_goal_planner(box_teacher)
    discrete = DQN("MultiInputPolicy", DiscretePointEnv(), learning_starts=10, batch_size=8, buffer_size=100).learn(20)
    with pytest.raises(ValueError, match=r"continuous.*DQN teacher's action space is Discrete"):
        distill_goal_planner(discrete)
    with pytest.raises(ValueError, match=r"env of the rollouts does not fit the SAC teacher: Observation spaces"):
        distill_goal_planner(teachers["SAC"], env=gym.make("Pendulum-v1"))
    with pytest.raises(TypeError, match=r"needs an SB3 model.*got dict"):
        distill_goal_planner({"policy": "SAC"})

    teachers["SAC"].save(tmp_path / "sac.zip")
    no_buffer = without_replay_buffer()  # a HER buffer needs an env to load
    with pytest.raises(ValueError, match=r"SAC teacher in an env, and it has none.*pass env="):
        distill_goal_planner(SAC.load(tmp_path / "sac.zip", custom_objects=no_buffer), source_task="PointGoalEnv")
    with pytest.raises(FileNotFoundError, match="No model file"):
        distill_goal_planner(tmp_path / "missing.zip")
    (tmp_path / "notes.zip").write_text("not a zip")
    GoalPlanner(2, net_arch=[4], metadata={"source_task": "PointGoalEnv"}).save(tmp_path / "planner.pt")
    for not_a_model in ("notes.zip", "planner.pt"):  # a torch file is a zip too, without SB3's data
        with pytest.raises(ValueError, match="is not an SB3 model"):
            distill_goal_planner(tmp_path / not_a_model, env=PointGoalEnv())
