"""
The changes to the RL Zoo that have no hook (:mod:`sb3_pilot.experiments.zoo_shim`): pinned to the rl_zoo3 versions
they were checked against, refused loudly when what they rely on changes, applied only while a command runs.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import rl_zoo3
import rl_zoo3.exp_manager
import rl_zoo3.train
import yaml
from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_pilot.envs.maze import Maze2DEnv
from sb3_pilot.experiments import zoo_shim
from sb3_pilot.experiments.evaluation import GoalEvalCallback
from sb3_pilot.experiments.zoo_plugin import register
from sb3_pilot.experiments.zoo_shim import (
    TESTED_RL_ZOO3_VERSIONS,
    PilotExperimentManager,
    check_rl_zoo3,
    record_video_calls_to,
    zoo_train_with,
)

MAZE = "Pilot/Maze2D-v0"


def test_pinned_to_the_installed_rl_zoo3() -> None:
    """A new rl_zoo3 fails here until zoo_shim's patches are read against it and its version added."""
    assert rl_zoo3.__version__ in TESTED_RL_ZOO3_VERSIONS, (
        f"rl_zoo3 {rl_zoo3.__version__} is installed, sb3_pilot.experiments.zoo_shim was checked against "
        f"{TESTED_RL_ZOO3_VERSIONS}: read rl_zoo3's train.py, exp_manager.py (ExperimentManager.__init__, "
        "read_hyperparameters, create_callbacks) and record_training.py against the shim, then add the version."
    )
    check_rl_zoo3()


def test_changed_names_are_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    """What the patches rely on, changed, is refused with its name before any patch is applied."""
    monkeypatch.setattr(rl_zoo3.exp_manager, "EvalCallback", GoalEvalCallback)
    with pytest.raises(RuntimeError, match=r"rl_zoo3 2\..*create_callbacks no longer builds SB3's EvalCallback"):
        check_rl_zoo3(["train"])
    monkeypatch.undo()
    monkeypatch.setattr(zoo_shim, "_ZOO_RECORD_VIDEO_CALL", 'subprocess.run(["python", "-m", "rl_zoo3.record_video"')
    with (
        pytest.raises(RuntimeError, match=r"record_training no longer records its models with subprocess\.run"),
        record_video_calls_to(["true"]),
    ):
        pass
    check_rl_zoo3(["train"])


def test_nothing_patched_at_import_or_registration() -> None:
    """Importing the zoo entry and registering leave rl_zoo3's modules as they are (the shim acts within commands)."""
    import sb3_pilot.experiments.zoo  # noqa: F401

    register()
    assert rl_zoo3.train.ExperimentManager is rl_zoo3.exp_manager.ExperimentManager
    assert rl_zoo3.exp_manager.EvalCallback is EvalCallback
    assert rl_zoo3.exp_manager.CheckpointCallback is CheckpointCallback
    assert not hasattr(rl_zoo3.exp_manager.ExperimentManager._preprocess_hyperparams, "__wrapped__")
    with zoo_train_with():
        assert rl_zoo3.train.ExperimentManager is PilotExperimentManager
    assert rl_zoo3.train.ExperimentManager is rl_zoo3.exp_manager.ExperimentManager


def test_record_video_calls_redirected() -> None:
    """The zoo's ``python -m rl_zoo3.record_video`` call runs the given command, with its arguments; others unchanged."""
    count_arguments = [sys.executable, "-c", "import sys; sys.exit(len(sys.argv))"]
    zoo_call = subprocess.call
    with record_video_calls_to(count_arguments):
        assert subprocess.call(["python", "-m", "rl_zoo3.record_video", "--env", "X"]) == 3  # -c, --env, X
        assert subprocess.call([*count_arguments, "a"]) == 2
    assert subprocess.call is zoo_call


def manager(tmp_path: Path, entry: dict[str, Any], **kwargs: Any) -> PilotExperimentManager:
    """:class:`PilotExperimentManager` on a YAML entry for the maze, as the zoo's ``train`` builds it."""
    register()
    tmp_path.mkdir()
    conf = tmp_path / "conf.yml"
    conf.write_text(yaml.safe_dump({MAZE: {"policy": "MultiInputPolicy", "n_timesteps": 10, **entry}}))
    return PilotExperimentManager(
        argparse.Namespace(), "sac", MAZE, str(tmp_path / "logs"), config=str(conf), seed=0, verbose=0, **kwargs
    )


def test_experiment_manager_changes(tmp_path: Path) -> None:
    """Evaluation with GoalEvalCallback (the zoo's otherwise), normalised checkpoints, and the YAML's env_kwargs for
    the evaluation env unless ``--eval-env-kwargs`` is given."""
    entry = {"env_kwargs": {"max_episode_steps": 7}, "buffer_size": 100}
    pilot = manager(tmp_path / "pilot", entry, eval_freq=5, save_freq=5, n_eval_episodes=2)
    pilot.read_hyperparameters()
    assert pilot.eval_env_kwargs == {"max_episode_steps": 7}
    given = manager(tmp_path / "given", entry, eval_env_kwargs={"max_episode_steps": 3})
    given.read_hyperparameters()
    assert given.eval_env_kwargs == {"max_episode_steps": 3}
    pilot.create_callbacks()
    (checkpoint,) = (callback for callback in pilot.callbacks if isinstance(callback, CheckpointCallback))
    (evaluation,) = (callback for callback in pilot.callbacks if isinstance(callback, EvalCallback))
    assert checkpoint.save_vecnormalize and type(evaluation) is GoalEvalCallback
    assert evaluation.eval_freq == 5 and evaluation.n_eval_episodes == 2
    assert evaluation.log_path == str(Path(pilot.save_path) / "evaluations")
    assert evaluation.callback_on_new_best is not None and evaluation.callback_on_new_best.parent is evaluation
    evaluation.eval_env.close()


def test_goal_eval_callback_from_eval_callback() -> None:
    """Every setting of an ``EvalCallback`` carries over (a new one in SB3 fails here until it is copied too)."""
    env = DummyVecEnv([Maze2DEnv])
    made = EvalCallback(
        env,
        callback_on_new_best=CheckpointCallback(1, "a"),
        callback_after_eval=CheckpointCallback(2, "b"),
        n_eval_episodes=3,
        eval_freq=4,
        log_path="logs/run",
        best_model_save_path="best",
        deterministic=False,
        render=True,
        verbose=0,
        warn=False,
    )
    ours = GoalEvalCallback.from_eval_callback(made)
    extra = {"evaluations_final_distance", "_episode_distances", "_warned_uncounted_end"}
    assert set(vars(ours)) - set(vars(made)) == extra
    for name, value in vars(made).items():
        assert getattr(ours, name) is value or getattr(ours, name) == value, name
    assert ours.callback_on_new_best.parent is ours and ours.callback.parent is ours
    env.close()
