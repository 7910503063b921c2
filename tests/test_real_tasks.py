"""
UDPO beside SAC on real registered tasks, not only on envs written for the tests: gymnasium-robotics' own goal tasks
(float64 observations, no VecNormalize) and a gymnasium Box task: short learn, predict, save/load, planned next state,
and on the goal tasks a distillation from the teacher's rollouts (the default labels) and from its plans.
"""

import os
from pathlib import Path

import gymnasium as gym
import gymnasium_robotics
import numpy as np
import pytest
from stable_baselines3 import SAC, HerReplayBuffer

from sb3_pilot import UDPO, distill_goal_planner

gym.register_envs(gymnasium_robotics)

# (id, episode length used here, steps): short episodes so that HER samples after the first ones
TASKS = [("FetchReach-v4", 50, 150), ("PointMaze_UMaze-v3", 50, 150), ("AntMaze_UMaze-v5", 50, 150), ("Pendulum-v1", 200, 250)]


def make(env_id: str, max_episode_steps: int) -> gym.Env:
    env = gym.make(env_id, max_episode_steps=max_episode_steps)
    if hasattr(env.unwrapped, "tmp_xml_file_path"):  # gymnasium-robotics' mazes leave their XML in the temp folder
        os.remove(env.unwrapped.tmp_xml_file_path)
    return env


@pytest.mark.parametrize(("env_id", "max_episode_steps", "steps"), TASKS)
def test_udpo_runs_where_sac_runs(env_id: str, max_episode_steps: int, steps: int, tmp_path: Path) -> None:
    env = make(env_id, max_episode_steps)
    goal_env = isinstance(env.observation_space, gym.spaces.Dict)
    kwargs = {
        "policy": "MultiInputPolicy" if goal_env else "MlpPolicy",
        "env": env,
        "learning_starts": max_episode_steps,
        "batch_size": 32,
        "seed": 0,
        "replay_buffer_class": HerReplayBuffer if goal_env else None,
    }
    obs, _ = env.reset(seed=1)
    if goal_env:
        assert obs["observation"].dtype == np.float64  # what broke UDPO once
    actions = {}
    for algo in (SAC, UDPO):
        model = algo(**kwargs, policy_kwargs={"net_arch": [32, 32]}).learn(steps)
        action, _ = model.predict(obs, deterministic=True)
        assert action.shape == env.action_space.shape and env.action_space.contains(action.astype(np.float32))
        model.save(tmp_path / algo.__name__)
        loaded = algo.load(tmp_path / algo.__name__, env=env)
        np.testing.assert_allclose(loaded.predict(obs, deterministic=True)[0], action, rtol=1e-5)
        actions[algo] = action
    planned = loaded.predict_next_state(obs)
    flat_state = sum(obs[key].size for key in obs if key != "desired_goal") if goal_env else obs.size
    assert planned.shape == (flat_state,) and np.all(np.isfinite(planned))
    if goal_env:  # the planner's goal slice is the achieved goal's coordinates
        assert loaded.policy.goal_slice == slice(flat_state - obs["achieved_goal"].size, flat_state)
        distill = {"n_samples": 200, "gradient_steps": 20, "batch_size": 32, "net_arch": [16]}
        distill["allow_unsuccessful_teacher"] = True  # a few hundred steps need not reach a goal: plumbing is tested
        for labels in ("rollouts", "planned"):  # rollouts in the model's own (float64) env, plans from its buffer
            planner = distill_goal_planner(model, labels=labels, **distill)
            landmark = planner.predict(obs["achieved_goal"], obs["desired_goal"])
            assert planner.metadata["source_task"] == env_id and landmark.shape == obs["achieved_goal"].shape
            assert np.all(np.isfinite(landmark))
            if labels == "rollouts":  # 4 episodes ended; the mazes report "success", Fetch "is_success"
                assert 0.0 <= planner.metadata["rollout_success"] <= 1.0
        model.learn(max_episode_steps, reset_num_timesteps=False)  # training goes on after the rollouts
    env.close()
