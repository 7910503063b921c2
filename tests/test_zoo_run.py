"""
Reading a zoo run back (:mod:`sb3_pilot.experiments.zoo_run`): one rule for ``env_kwargs``, the zoo's, so that the
task options read from a run's saved settings are those the zoo trained it with.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest
import yaml
from rl_zoo3.exp_manager import ExperimentManager

from sb3_pilot.common.saved_models import vecnormalize_path, without_replay_buffer, zoo_settings_dir
from sb3_pilot.experiments.zoo_plugin import register
from sb3_pilot.experiments.zoo_run import env_kwargs_rule, zoo_env_kwargs

MAZE, MAZE_NAME = "Pilot/Maze2D-v0", "Pilot-Maze2D-v0"


def test_env_kwargs_rule() -> None:
    """The command line's ``--env-kwargs`` replace the YAML entry's whole (not key by key); absent, the YAML's hold."""
    assert env_kwargs_rule({"a": 1, "b": 2}, {"b": 3}) == {"b": 3}
    assert env_kwargs_rule({"a": 1}, None) == {"a": 1} == env_kwargs_rule({"a": 1}, {})
    assert env_kwargs_rule(None, {"b": 3}) == {"b": 3}
    assert env_kwargs_rule(None, None) == {}
    yaml_entry = {"a": 1}
    assert env_kwargs_rule(yaml_entry, None) is not yaml_entry  # a new dict


@pytest.mark.parametrize(
    ("yaml_kwargs", "command_line"),
    [
        ({"max_episode_steps": 7, "goal_distribution": "uniform"}, None),
        (None, {"max_episode_steps": 5}),
        ({"max_episode_steps": 7, "goal_distribution": "uniform"}, {"max_episode_steps": 5}),
    ],
)
def test_read_back_as_the_zoo_trained(tmp_path: Path, yaml_kwargs: dict[str, Any] | None, command_line: Any) -> None:
    """The zoo's ExperimentManager reads a YAML entry and a command line, and saves its settings; the task options read
    back from them (:func:`zoo_env_kwargs`) are those the zoo's training env gets."""
    register()
    conf = tmp_path / "conf.yml"
    entry = {"policy": "MultiInputPolicy", "n_timesteps": 10, **({"env_kwargs": yaml_kwargs} if yaml_kwargs else {})}
    conf.write_text(yaml.safe_dump({MAZE: entry}))
    args = argparse.Namespace(algo="sac", env=MAZE, env_kwargs=command_line)
    manager = ExperimentManager(args, "sac", MAZE, str(tmp_path / "logs"), env_kwargs=command_line, config=str(conf))
    hyperparams, saved = manager.read_hyperparameters()
    manager._preprocess_hyperparams(hyperparams)  # sets the training env's env_kwargs
    manager.create_log_folder()
    manager._save_config(saved)  # config.yml and args.yml, as after training
    model_path = Path(manager.save_path) / f"{MAZE_NAME}.zip"
    assert zoo_settings_dir(model_path) == Path(manager.params_path)
    assert zoo_env_kwargs(model_path) == manager.env_kwargs == env_kwargs_rule(yaml_kwargs, command_line)


def test_saved_model_rules() -> None:
    """Where the zoo keeps a model's statistics, and a new custom_objects dict each call (a model keeps its own)."""
    model = Path("logs/sac/Pilot-Maze2D-v0_1/Pilot-Maze2D-v0.zip")
    assert vecnormalize_path(model) == Path("logs/sac/Pilot-Maze2D-v0_1/Pilot-Maze2D-v0/vecnormalize.pkl")
    first, second = without_replay_buffer(), without_replay_buffer()
    assert first == second == {"replay_buffer_class": None, "replay_buffer_kwargs": {}, "buffer_size": 1}
    assert first["replay_buffer_kwargs"] is not second["replay_buffer_kwargs"]
