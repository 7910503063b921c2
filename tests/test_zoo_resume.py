"""``python -m sb3_pilot.experiments.zoo train --checkpoint-freq N [--resume]``: a run stopped at N env steps goes on
from its checkpoint in its own folder, to the counters of a run never stopped; bad input refused before training;
the challenges refuse an unknown budget with the list."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from sb3_pilot.common.saved_models import without_replay_buffer
from sb3_pilot.experiments.challenges.__main__ import main as challenges_main
from sb3_pilot.experiments.challenges.definitions import BUDGETS
from sb3_pilot.experiments.zoo import main as zoo_main
from sb3_pilot.sac import LeanSAC

RUN = Path("logs", "lean_sac", "Pilot-Maze2D-v0_1")
PARAMS = ("learning_starts:60", "batch_size:16", "buffer_size:500", "policy_kwargs:dict(net_arch=[16])")


def train(folder: Path, monkeypatch: pytest.MonkeyPatch, steps: int, *extra: str, params: tuple[str, ...] = PARAMS) -> None:
    """The zoo's train of LeanSAC + HER on Pilot/Maze2D-v0, in ``folder``, in this process."""
    folder.mkdir(exist_ok=True)
    monkeypatch.chdir(folder)
    monkeypatch.setattr(sys, "argv", list(sys.argv))  # the zoo entry sets it
    common = ["--algo", "lean_sac", "--env", "Pilot/Maze2D-v0", "-f", "logs", "--num-threads", "1", "--seed", "0"]
    common += ["-n", str(steps), "--eval-freq", "100", "--eval-episodes", "2", *extra]
    zoo_main(["train", *common, "-params", *params])


def test_resumed_run_goes_on_in_its_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Stopped at 100 steps (a checkpoint), resumed to 200: same folder, evaluations going on, the uninterrupted
    counters (50-step episodes: the interrupted one ends at the checkpoint)."""
    train(tmp_path / "stopped", monkeypatch, 100, "--checkpoint-freq", "100")
    checkpoint = tmp_path / "stopped" / RUN / "checkpoint" / "checkpoint.json"
    assert json.loads(checkpoint.read_text())["num_timesteps"] == 100
    train(tmp_path / "stopped", monkeypatch, 200, "--checkpoint-freq", "100", "--resume")
    assert not (tmp_path / "stopped" / RUN.with_name("Pilot-Maze2D-v0_2")).exists()
    assert json.loads(checkpoint.read_text())["num_timesteps"] == 200
    with np.load(tmp_path / "stopped" / RUN / "evaluations.npz") as data:
        assert data["timesteps"].tolist() == [100, 200] and len(data["final_distances"]) == 2
    train(tmp_path / "whole", monkeypatch, 200)
    resumed, whole = (
        LeanSAC.load(tmp_path / name / RUN / "Pilot-Maze2D-v0.zip", custom_objects=without_replay_buffer())
        for name in ("stopped", "whole")
    )
    assert (resumed.num_timesteps, resumed._n_updates) == (whole.num_timesteps, whole._n_updates)
    assert resumed.num_timesteps == 200 and resumed._n_updates > 0
    critic_steps = [state["step"].item() for state in resumed.critic.optimizer.state.values()]
    assert set(critic_steps) == {resumed._n_updates}  # Adam's state went on from the checkpoint's


def test_resume_bad_input(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """--resume without a checkpoint, of other settings, or without --checkpoint-freq: refused before training."""
    with pytest.raises(SystemExit, match=r"--resume: no checkpoint in logs/lean_sac/ \(no run of Pilot-Maze2D-v0\)"):
        train(tmp_path, monkeypatch, 100, "--checkpoint-freq", "100", "--resume")
    with pytest.raises(SystemExit, match="give the --checkpoint-freq it was trained with"):
        train(tmp_path, monkeypatch, 100, "--resume")
    train(tmp_path, monkeypatch, 100)  # no checkpoint kept
    with pytest.raises(SystemExit, match=r"no checkpoint in logs/lean_sac/Pilot-Maze2D-v0_1/checkpoint"):
        train(tmp_path, monkeypatch, 200, "--checkpoint-freq", "100", "--resume")
    train(tmp_path, monkeypatch, 100, "--checkpoint-freq", "100")  # run 2, with its checkpoint
    other = (*PARAMS[:-1], "learning_rate:0.001", PARAMS[-1])
    with pytest.raises(SystemExit, match=r"another run \(hyperparams.learning_rate: 0.0003 in the checkpoint, 0.001 now"):
        train(tmp_path, monkeypatch, 200, "--checkpoint-freq", "100", "--resume", params=other)


def test_unknown_budget_refused_with_the_list(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        challenges_main(["high-dim-action", "--budget", "gpu"])
    error = capsys.readouterr().err
    assert "invalid choice: 'gpu'" in error and all(name in error for name in BUDGETS)
