"""Reliability battery: bad input is refused before any work with an error naming it, and nothing is lost or left."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from goal_envs import PointGoalEnv
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import EvalCallback
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_pilot import UDPO, GoalPlanner, LandmarkGuidance, PilotBonusWrapper
from sb3_pilot.experiments.challenges import run_challenge
from sb3_pilot.experiments.challenges.stages import STAGE_MARKER

NOT_FINITE = [float("nan"), float("inf"), -float("inf")]


@pytest.fixture(scope="module")
def planner() -> GoalPlanner:
    return GoalPlanner(2, [8], metadata={"source_task": "PointGoalEnv"})


@pytest.mark.parametrize("value", NOT_FINITE)
@pytest.mark.parametrize(
    "argument", ["planner_coef", "learning_rate", "planner_learning_rate", "inverse_dynamics_learning_rate", "gamma", "tau"]
)
def test_udpo_refuses_non_finite_numbers(argument: str, value: float) -> None:
    with pytest.raises(ValueError, match=rf"{argument}.*finite"):
        UDPO("MultiInputPolicy", PointGoalEnv(), **{argument: value})


@pytest.mark.parametrize("value", [*NOT_FINITE, 2.5])
def test_integer_arguments_refuse_non_integers(planner: GoalPlanner, value: float) -> None:
    with pytest.raises(ValueError, match="inverse_dynamics_interval"):
        UDPO("MultiInputPolicy", PointGoalEnv(), inverse_dynamics_interval=value)
    with pytest.raises(ValueError, match="horizon"):
        LandmarkGuidance(PointGoalEnv(), planner, horizon=value)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="horizon"):
        planner.plan(np.zeros(2), np.ones(2), horizon=value)  # type: ignore[arg-type]


@pytest.mark.parametrize("value", NOT_FINITE)
def test_transfer_wrappers_refuse_non_finite_numbers(planner: GoalPlanner, value: float) -> None:
    with pytest.raises(ValueError, match="beta must be a finite number"):
        PilotBonusWrapper(PointGoalEnv(), planner, beta=value)
    if value > 0:  # -inf is refused for being negative, too
        with pytest.raises(ValueError, match="switch_distance must be a finite number"):
            LandmarkGuidance(PointGoalEnv(), planner, switch_distance=value)


def test_multi_input_policy_needs_a_dict_observation() -> None:
    with pytest.raises(ValueError, match=r"MultiInputPolicy needs a Dict observation space.*MlpPolicy"):
        UDPO("MultiInputPolicy", "Pendulum-v1")


def test_goal_planner_load_refuses_other_files(planner: GoalPlanner, tmp_path: Path) -> None:
    th.save({"weights": th.zeros(3)}, tmp_path / "other.pt")
    th.save(th.nn.Linear(2, 2).state_dict(), tmp_path / "state_dict.pt")
    with zipfile.ZipFile(tmp_path / "archive.zip", "w") as archive:
        archive.writestr("data.txt", "not a planner")
    (tmp_path / "garbage.pt").write_bytes(np.random.default_rng(0).bytes(256))
    (tmp_path / "pickle_header.pt").write_bytes(b"\x80\x04" + np.random.default_rng(1).bytes(64))
    (tmp_path / "empty.pt").write_bytes(b"")
    SAC("MlpPolicy", "Pendulum-v1").save(tmp_path / "model.zip")
    for name in ("other.pt", "state_dict.pt", "archive.zip", "garbage.pt", "pickle_header.pt", "empty.pt", "model.zip"):
        with pytest.raises(ValueError, match=r"is not a goal planner written by GoalPlanner\.save"):
            GoalPlanner.load(tmp_path / name)
    with pytest.raises(FileNotFoundError, match="No goal planner file"):
        GoalPlanner.load(tmp_path / "missing.pt")
    planner.save(tmp_path / "planner.pt")
    assert GoalPlanner.load(tmp_path / "planner.pt").goal_dim == 2


def test_ant_maze_leaves_no_temporary_files() -> None:
    env = gym.make("Pilot/AntMaze-v0")
    xml = Path(env.unwrapped.maze_env.tmp_xml_file_path)
    assert not xml.exists()
    env.reset(seed=0)
    env.step(env.action_space.sample())
    env.close()
    assert not xml.exists()


@pytest.mark.parametrize("learning_starts", [1000, 10])
def test_plan_error_is_computed_from_stored_transitions(learning_starts: int) -> None:
    """
    With a planner that plans no move (mean of ``s' - s`` zero), the plan error of each stored transition is
    ``mean((s' - s)^2)`` over the planner state (observation + achieved goal), computed here from the buffer with
    numpy: for warm-up's random actions (planner run for the error) and for the policy's (the planner's mean of the
    acting forward pass reused). An evaluation on an env with another number of envs (run between acting and storing
    the transition) changes nothing.
    """
    model = UDPO(
        "MultiInputPolicy",
        PointGoalEnv(max_episode_steps=100),
        learning_starts=learning_starts,
        gradient_steps=0,  # the planner stays the zero-move planner
        seed=0,
    )
    last_layer = model.policy.state_planner.net[-1]
    with th.no_grad():
        last_layer.weight.zero_()
        last_layer.bias.zero_()
    eval_env = DummyVecEnv([PointGoalEnv, PointGoalEnv])
    model.learn(40, callback=EvalCallback(eval_env, eval_freq=7, n_eval_episodes=2, verbose=0))
    buffer = model.replay_buffer

    def state(observations: dict[str, np.ndarray]) -> np.ndarray:
        return np.concatenate([observations["observation"][:40, 0], observations["achieved_goal"][:40, 0]], axis=1)

    expected = np.mean((state(buffer.next_observations) - state(buffer.observations)) ** 2, axis=1)
    np.testing.assert_allclose(model._plan_errors, expected, rtol=1e-5)


def _summary_without_times(path: Path) -> dict:
    summary = json.loads(path.read_text())
    summary.pop("wall_time_s")
    for stage in summary["stages"].values():
        stage.pop("wall_time_s")
    return summary


def test_challenge_resumes_when_killed_and_when_moved(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """
    A challenge killed in the middle of a stage and started again finishes, with the summary of an uninterrupted run
    (but wall times: CPU training is deterministic); a finished results folder moved elsewhere resumes (skips every
    stage) with the same summary.
    """
    whole = run_challenge("high-dim-action", "smoke", seeds=[0], root=tmp_path / "whole")
    command = [sys.executable, "-m", "sb3_pilot.experiments.challenges", "high-dim-action", "--budget", "smoke"]
    command += ["--root", str(tmp_path / "killed"), "--no-progress"]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    pilot_dir = tmp_path / "killed" / "high-dim-action" / "models" / "seed_0" / "pilot"
    deadline = time.monotonic() + 600
    while not (pilot_dir / "udpo").exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    assert process.poll() is None, "the run ended before its 'pilot' stage could be interrupted"
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    assert pilot_dir.exists() and not (pilot_dir / STAGE_MARKER).exists()
    resumed = run_challenge("high-dim-action", "smoke", seeds=[0], root=tmp_path / "killed")
    assert resumed["methods"] == whole["methods"]
    killed_summary = tmp_path / "killed" / "high-dim-action" / "summary.json"
    assert _summary_without_times(killed_summary) == _summary_without_times(tmp_path / "whole/high-dim-action/summary.json")

    shutil.move(tmp_path / "whole", tmp_path / "moved")
    capsys.readouterr()
    run_challenge("high-dim-action", "smoke", seeds=[0], root=tmp_path / "moved")
    assert capsys.readouterr().out.count("skipped") == 3
    assert _summary_without_times(tmp_path / "moved/high-dim-action/summary.json") == _summary_without_times(killed_summary)
