"""The evaluation that records the final distance to the goal, and the zoo's use of it."""

from pathlib import Path

import numpy as np
from goal_envs import PointGoalEnv
from stable_baselines3 import SAC, HerReplayBuffer
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from sb3_pilot.experiments.evaluation import GoalEvalCallback, final_distance, load_final_distances


def test_final_distance_of_a_terminal_observation() -> None:
    info = {"terminal_observation": {"achieved_goal": np.array([0.0, 3.0]), "desired_goal": np.array([4.0, 0.0])}}
    assert final_distance(info) == 5.0
    assert final_distance({}) is None and final_distance({"terminal_observation": np.zeros(3)}) is None


def test_goal_eval_callback_records_final_distances(tmp_path: Path) -> None:
    """One mean distance per evaluation, in raw coordinates even under VecNormalize, saved beside the successes."""
    env = VecNormalize(DummyVecEnv([lambda: Monitor(PointGoalEnv())]), norm_reward=False)
    eval_env = VecNormalize(DummyVecEnv([lambda: Monitor(PointGoalEnv())]), norm_reward=False, training=False)
    callback = GoalEvalCallback(eval_env, eval_freq=50, n_eval_episodes=3, log_path=str(tmp_path), verbose=0)
    model = SAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, learning_starts=60, batch_size=16, seed=0)
    model.learn(150, callback=callback)
    distances = load_final_distances(tmp_path / "evaluations.npz")
    with np.load(tmp_path / "evaluations.npz") as data:
        assert len(distances) == len(data["timesteps"]) == 3 and len(data["successes"]) == 3
    # PointGoalEnv lives in [-1, 1]^2: raw distances are below 2 * sqrt(2); the success threshold is 0.1
    assert np.all((distances >= 0) & (distances <= 2 * np.sqrt(2)))
    successes_only = np.array([np.mean(row) for row in np.load(tmp_path / "evaluations.npz")["successes"]])
    assert np.all(distances[successes_only == 1.0] <= 0.1 + 1e-6)
