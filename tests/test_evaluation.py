"""The evaluation that records the final distance to the goal, and the zoo's use of it."""

import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
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


class EndsEveryOtherEpisodeEarly(gym.Wrapper):
    """Ends every other episode after 3 steps, unsuccessfully, as a wrapper above the zoo's Monitor would (the
    controller recipe's flip)."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        self.episodes, self.steps = 0, 0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self.episodes, self.steps = self.episodes + 1, 0
        return self.env.reset(**kwargs)

    def step(self, action: np.ndarray) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        if self.episodes % 2 == 0 and self.steps == 3:
            return observation, reward, True, truncated, {**info, "is_success": False}
        return observation, reward, terminated, truncated, info


@pytest.mark.parametrize("monitor_on_top", [False, True])
def test_episodes_a_wrapper_above_the_monitor_ends(tmp_path: Path, monitor_on_top: bool) -> None:
    """Every evaluation records one success per counted episode (no ragged ``successes``, which SB3 cannot save);
    the early ends count only with a Monitor above the wrapper, else they are left out with a warning."""

    def make() -> gym.Env:
        env = EndsEveryOtherEpisodeEarly(Monitor(PointGoalEnv()))
        return Monitor(env) if monitor_on_top else env

    eval_env = DummyVecEnv([make])
    callback = GoalEvalCallback(eval_env, eval_freq=50, n_eval_episodes=4, log_path=str(tmp_path), verbose=0)
    model = SAC("MultiInputPolicy", DummyVecEnv([make]), learning_starts=60, batch_size=16, seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.learn(100, callback=callback)
    uncounted = [warning for warning in caught if "ended without its Monitor's record" in str(warning.message)]
    assert len(uncounted) == (0 if monitor_on_top else 1)  # warned once
    with np.load(tmp_path / "evaluations.npz") as data:
        assert data["successes"].shape == (2, 4) and data["ep_lengths"].shape == (2, 4)
        assert (3 in data["ep_lengths"]) == monitor_on_top  # the early ends, counted as episodes
