"""MEGA's behaviour goals (sb3_pilot.baselines): the density, the choice, the training env's side, HER, the bonus, the zoo."""

import os
import pickle
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from goal_envs import PointGoalEnv
from gymnasium import spaces
from scipy.stats import multivariate_normal
from stable_baselines3 import PPO, SAC, HerReplayBuffer
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnvWrapper, VecFrameStack, VecNormalize

from sb3_pilot import UDPO, GoalPlanner, PilotBonusWrapper, PilotHerReplayBuffer
from sb3_pilot.baselines import KernelDensity, MegaCallback, MegaGoalWrapper

MAZE = "Pilot/Maze2D-v0"
FAST = {
    "buffer_size": 2000,
    "learning_starts": 100,
    "batch_size": 32,
    "policy_kwargs": {"net_arch": [32, 32]},
    "seed": 0,
    "device": "cpu",
}


def maze_venv(wrapper=None) -> DummyVecEnv:
    return DummyVecEnv([lambda: wrapper(gym.make(MAZE)) if wrapper else gym.make(MAZE)])


class GoalSpy(VecEnvWrapper):
    """Counts the observations whose desired goal is not the maze's own goal."""

    def __init__(self, venv):
        super().__init__(venv)
        self.observations = self.not_env_goal = 0

    def _check(self, observation):
        self.observations += 1
        self.not_env_goal += not np.array_equal(observation["desired_goal"], np.float32(self.venv.get_attr("goal")))
        return observation

    def reset(self):
        return self._check(self.venv.reset())

    def step_wait(self):
        observation, rewards, dones, infos = self.venv.step_wait()
        return self._check(observation), rewards, dones, infos


def stored(buffer: HerReplayBuffer) -> dict[str, np.ndarray]:
    """The transitions of env 0 stored so far."""
    n = buffer.pos
    return {
        "desired": buffer.observations["desired_goal"][:n, 0],
        "next_desired": buffer.next_observations["desired_goal"][:n, 0],
        "achieved": buffer.observations["achieved_goal"][:n, 0],
        "next_achieved": buffer.next_observations["achieved_goal"][:n, 0],
        "rewards": buffer.rewards[:n, 0],
        "episode": buffer.ep_start[:n, 0],
    }


def check_her_consistency(data: dict[str, np.ndarray], compute_reward) -> None:
    """Behaviour goals are earlier achieved goals, fixed per episode, and the stored rewards are theirs."""
    episodes = np.unique(data["episode"])
    assert len(episodes) >= 3
    # (VecNormalize gives terminal observations back through normalize / unnormalize: float32 round-off)
    np.testing.assert_allclose(data["desired"], data["next_desired"], atol=1e-5)
    for start in episodes:
        goals = data["desired"][data["episode"] == start]
        assert np.all(goals == goals[0])
        if start > 0:  # the first episode starts with an empty buffer: the env's goal
            assert np.any(np.all(data["next_achieved"][:start] == goals[0], axis=1)), "not an achieved goal of the buffer"
    np.testing.assert_allclose(data["rewards"], compute_reward(data), atol=1e-6)


def test_kernel_density_matches_gaussian_mixture() -> None:
    rng = np.random.default_rng(0)
    samples = rng.normal([3.0, -1.0], [2.0, 0.5], size=(50, 2))
    points = rng.normal(size=(7, 2))
    density = KernelDensity(bandwidth=0.3).fit(samples)
    mean, std = samples.mean(axis=0), samples.std(axis=0) + 1e-4
    kernels = [multivariate_normal((s - mean) / std, 0.09 * np.eye(2)) for s in samples]
    expected = np.log(np.mean([k.pdf((points - mean) / std) for k in kernels], axis=0))
    np.testing.assert_allclose(density.log_density(points), expected, rtol=1e-6)
    with pytest.raises(ValueError, match="NaN or infinite"):
        density.fit(np.array([[0.0, np.nan]]))
    with pytest.raises(ValueError, match="bandwidth"):
        KernelDensity(bandwidth=0.0)


def test_choice_prefers_the_rare_reachable_goal() -> None:
    """A dense cluster and one rare point: the rare one wins while its value passes the cut-off, else the cluster."""
    rng = np.random.default_rng(0)
    cluster = rng.normal(0.0, 0.05, size=(200, 2))
    rare = np.array([[3.0, 3.0]])
    mega = MegaCallback()
    mega.density.fit(np.concatenate([cluster, rare]))
    candidates = np.concatenate([cluster[:9], rare])[None]
    values = np.full((1, 10), -1.0)
    np.testing.assert_array_equal(mega.choose(candidates, values)[0], rare[0])
    values[0, -1] = -10.0  # below the cut-off (-3): deemed not reachable yet
    chosen = mega.choose(candidates, values)[0]
    assert not np.array_equal(chosen, rare[0]) and any(np.array_equal(chosen, c) for c in cluster[:9])
    values = np.linspace(-20.0, -11.0, 10)[None]  # none passes: the highest value
    np.testing.assert_array_equal(mega.choose(candidates, values)[0], rare[0])


@pytest.mark.parametrize("algo", [SAC, UDPO])
def test_training_pursues_buffer_goals_and_evaluation_the_envs(algo) -> None:
    """On Pilot/Maze2D-v0: behaviour goals from the buffer, HER-consistent rewards; evaluation on the env's goals."""
    env = GoalSpy(MegaGoalWrapper(maze_venv()))
    eval_env = GoalSpy(MegaGoalWrapper(maze_venv()))
    mega = MegaCallback()
    evaluation = EvalCallback(eval_env, eval_freq=150, n_eval_episodes=2, verbose=0)
    model = algo("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, **FAST)
    model.learn(300, callback=[mega, evaluation])
    maze = env.venv.envs[0].unwrapped
    check_her_consistency(stored(model.replay_buffer), lambda d: maze.compute_reward(d["next_achieved"], d["desired"], None))
    assert env.not_env_goal > 200 and mega.lowest_cutoff == pytest.approx(-(1 - 0.99**40) / 0.01)
    assert eval_env.observations > 200 and eval_env.not_env_goal == 0
    # after learn, a new episode of the training env pursues the env's goal again
    assert env.venv.source is None
    observation = env.reset()
    np.testing.assert_array_equal(observation["desired_goal"][0], maze.goal.astype(np.float32))


def test_composes_with_the_bonus_and_vec_normalize() -> None:
    """PilotBonusWrapper inside, VecNormalize outside: stored rewards are sparse + bonus of the behaviour goal."""
    planner = GoalPlanner(2, net_arch=[8], metadata={"source_task": MAZE})
    env = VecNormalize(MegaGoalWrapper(maze_venv(lambda e: PilotBonusWrapper(e, planner, beta=0.5))))
    model = SAC("MultiInputPolicy", env, replay_buffer_class=PilotHerReplayBuffer, **FAST)
    model.learn(300, callback=MegaCallback())
    bonus_env = env.venv.envs[0]
    data = stored(model.replay_buffer)

    def reward(d):
        info = {"previous_achieved_goal": d["achieved"]}
        return bonus_env.compute_reward(d["next_achieved"], d["desired"], info)

    check_her_consistency(data, reward)
    assert np.any(reward(data) % 1 != 0)  # the bonus is there


def test_go_explore_stores_the_actions_taken() -> None:
    """Go-explore: after the behaviour goal, random actions are taken, and the replay buffer stores those actions."""

    class Counting(MegaCallback):
        explored = 0

        def _on_step(self) -> bool:
            self.explored += int(self.goal_wrapper.explored.sum())
            return super()._on_step()

    env = MegaGoalWrapper(DummyVecEnv([PointGoalEnv] * 2), success_distance=0.5)
    mega = Counting(go_explore=1.0, max_episode_steps=25)
    model = SAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, **FAST)
    model.learn(600, callback=mega)
    assert mega.explored > 50 and env.go_explore_rate == 0.0  # off again after learn
    buffer, n = model.replay_buffer, model.replay_buffer.pos
    velocity, next_velocity = buffer.observations["observation"][:n, :, 2:], buffer.next_observations["observation"][:n, :, 2:]
    # v' = damping v + force_scale a: the stored action is the one the env executed
    np.testing.assert_allclose(next_velocity, 0.5 * velocity + 0.1 * buffer.actions[:n], atol=1e-5)
    with pytest.raises(ValueError, match="bounded Box action space"):
        model = SAC("MultiInputPolicy", MegaGoalWrapper(maze_venv()), replay_buffer_class=HerReplayBuffer, **FAST)
        model.action_space = model.env.action_space = spaces.Box(-np.inf, np.inf, (2,))
        model.learn(10, callback=MegaCallback())


def test_bad_input_is_refused_before_training() -> None:
    with pytest.raises(ValueError, match="needs a goal env"):
        MegaGoalWrapper(DummyVecEnv([lambda: gym.make("Pendulum-v1")]))

    class DiscreteGoals(PointGoalEnv):
        def __init__(self):
            super().__init__()
            self.observation_space = spaces.Dict(
                {
                    "observation": self.observation_space["observation"],
                    "achieved_goal": spaces.Discrete(4),
                    "desired_goal": spaces.Discrete(4),
                }
            )

    with pytest.raises(ValueError, match="1-D float Box"):
        MegaGoalWrapper(DummyVecEnv([DiscreteGoals]))
    with pytest.raises(ValueError, match="no distance_threshold"):
        MegaGoalWrapper(DummyVecEnv([PointGoalEnv]))
    MegaGoalWrapper(DummyVecEnv([PointGoalEnv]), success_distance=0.1)  # unbounded or bounded Box goals: fine
    with pytest.raises(ValueError, match=r"wrapped in sb3_pilot\.baselines\.MegaGoalWrapper"):
        SAC("MultiInputPolicy", maze_venv(), replay_buffer_class=HerReplayBuffer, **FAST).learn(10, callback=MegaCallback())
    with pytest.raises(ValueError, match="wrap it in VecNormalize"):
        model = SAC(
            "MultiInputPolicy", MegaGoalWrapper(VecNormalize(maze_venv())), replay_buffer_class=HerReplayBuffer, **FAST
        )
        model.learn(10, callback=MegaCallback())
    with pytest.raises(ValueError, match="VecFrameStack"):
        model = SAC(
            "MultiInputPolicy", VecFrameStack(MegaGoalWrapper(maze_venv()), 2), replay_buffer_class=HerReplayBuffer, **FAST
        )
        model.learn(10, callback=MegaCallback())
    with pytest.raises(TypeError, match="replay buffer"):
        PPO("MultiInputPolicy", MegaGoalWrapper(maze_venv()), n_steps=64, device="cpu").learn(10, callback=MegaCallback())
    with pytest.raises(ValueError, match="success_bounds"):
        MegaCallback(success_bounds=(0.7, 0.3))
    with pytest.raises(ValueError, match="go_explore"):
        MegaCallback(go_explore=-0.1)


def test_zoo_yaml_entry(tmp_path: Path) -> None:
    """``--conf-file cpu/sac_mega.yml`` trains SAC + HER + MEGA in the RL Zoo; its buffer holds behaviour goals."""
    command = [sys.executable, "-m", "sb3_pilot.experiments.zoo", "train", "--algo", "sac", "--env", MAZE]
    command += ["--conf-file", "cpu/sac_mega.yml", "-n", "300", "-f", "logs", "--num-threads", "1", "--seed", "0"]
    command += ["--eval-freq", "150", "--eval-episodes", "2", "--save-replay-buffer", "-params", "learning_starts:100"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    result = subprocess.run(command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    run = tmp_path / "logs" / "sac" / "Pilot-Maze2D-v0_1"
    with open(run / "replay_buffer.pkl", "rb") as file:
        buffer = pickle.load(file)
    maze = gym.make(MAZE).unwrapped
    check_her_consistency(stored(buffer), lambda d: maze.compute_reward(d["next_achieved"], d["desired"], None))
    assert len(np.load(run / "evaluations.npz")["timesteps"]) == 2


@pytest.mark.parametrize("folder", ["", "cpu/"])
def test_yaml_entries_are_sacs_plus_mega(folder: str) -> None:
    """hyperparams/[cpu/]sac_mega.yml: [cpu/]sac.yml's entries, same values, plus MEGA's wrapper and callback."""
    import yaml

    from sb3_pilot.experiments.zoo import hyperparams_dir

    mega = yaml.safe_load((hyperparams_dir() / f"{folder}sac_mega.yml").read_text())
    sac = yaml.safe_load((hyperparams_dir() / f"{folder}sac.yml").read_text())
    assert set(mega) == {"Pilot/Maze2D-v0", "Pilot/AntMaze-v0", "Pilot/AntLocomotion-v0", "Pilot/Maze2DCar-v0"}
    for env_id, entry in mega.items():
        assert entry.pop("vec_env_wrapper") == "sb3_pilot.baselines.MegaGoalWrapper", env_id
        assert entry.pop("callback") == [{"sb3_pilot.baselines.MegaCallback": {"go_explore": 0.1}}], env_id
        assert entry == sac[env_id], env_id
