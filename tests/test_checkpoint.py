"""Resumable checkpoints (sb3_pilot.common.checkpoint): a pixel run stopped and resumed goes on with its counters, its
networks and optimizers, and its replay buffer (frames compressed in chunks); bad input refused."""

from __future__ import annotations

import json
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import torch as th
from image_envs import ImageGoalEnv
from stable_baselines3 import HerReplayBuffer
from stable_baselines3.common.vec_env import DummyVecEnv

from sb3_pilot.common.checkpoint import (
    CHECKPOINT_FILE,
    CheckpointEvery,
    load_checkpoint,
    read_checkpoint,
    save_checkpoint,
)
from sb3_pilot.pixels import PixelGoalSACPolicy
from sb3_pilot.sac import LeanSAC
from sb3_pilot.transfer.bonus import PREVIOUS_ACHIEVED_GOAL, PilotHerReplayBuffer

SETTINGS = {"task": "image-goal", "learning_rate": 3e-4}


def make_model(buffer_size: int = 200, seed: int = 0, replay_buffer_class: type[HerReplayBuffer] = HerReplayBuffer) -> LeanSAC:
    return LeanSAC(
        PixelGoalSACPolicy,
        DummyVecEnv([ImageGoalEnv]),
        replay_buffer_class=replay_buffer_class,
        buffer_size=buffer_size,
        learning_starts=20,
        batch_size=8,
        policy_kwargs={"net_arch": [16], "features_extractor_kwargs": {"random_shift": 2}},
        seed=seed,
        device="cpu",
    )


def load(folder: Path, settings: dict[str, Any] = SETTINGS) -> LeanSAC:
    model = load_checkpoint(folder, LeanSAC, DummyVecEnv([ImageGoalEnv]), settings, device="cpu")
    assert isinstance(model, LeanSAC)
    return model


def optimizer_states(model: LeanSAC) -> list[dict[str, Any]]:
    return [optimizer.state_dict() for optimizer in (model.actor.optimizer, model.critic.optimizer, model.ent_coef_optimizer)]


def assert_same_buffer(first: HerReplayBuffer, second: HerReplayBuffer, rows: int) -> None:
    assert (first.pos, first.full) == (second.pos, second.full)
    for entry in ("observations", "next_observations"):
        for key in getattr(first, entry):
            np.testing.assert_array_equal(getattr(first, entry)[key][:rows], getattr(second, entry)[key][:rows], entry + key)
    for name in ("actions", "rewards", "ep_start"):
        np.testing.assert_array_equal(getattr(first, name)[:rows], getattr(second, name)[:rows], name)


def test_resume_goes_on_where_training_stopped(tmp_path: Path) -> None:
    """
    Stopped mid-episode at 45 steps and resumed: the same networks, optimizer states, temperature, counters and buffer
    (its interrupted episode truncated); 30 more steps reach the counters of the run that was never stopped.
    """
    model = make_model()
    model.learn(45)
    folder = tmp_path / "checkpoint"
    save_checkpoint(model, folder, SETTINGS)
    resumed = load(folder)
    assert (resumed.num_timesteps, resumed._n_updates, resumed._episode_num) == (45, model._n_updates, 4)
    for old, new in zip(model.policy.state_dict().values(), resumed.policy.state_dict().values(), strict=True):
        assert th.equal(old, new)
    for old, new in zip(optimizer_states(model), optimizer_states(resumed), strict=True):
        assert old["state"].keys() == new["state"].keys()
        for index, moments in old["state"].items():
            for name, value in moments.items():
                assert th.equal(value, new["state"][index][name]), name
    assert th.equal(model.log_ent_coef, resumed.log_ent_coef)
    assert_same_buffer(model.replay_buffer, resumed.replay_buffer, 45)
    # the interrupted episode (rows 40-44) ends at the checkpoint
    assert resumed.replay_buffer.dones[44, 0] and resumed.replay_buffer.ep_length[40:45, 0].tolist() == [5] * 5
    assert model.replay_buffer.ep_length[40, 0] == 0  # still running in the uninterrupted model
    # both go on for 30 steps: the same counters and as many optimizer steps
    model.learn(30, reset_num_timesteps=False)
    resumed.learn(30, reset_num_timesteps=False)
    assert (resumed.num_timesteps, resumed._n_updates, resumed.replay_buffer.pos) == (75, model._n_updates, 75)
    for old, new in zip(optimizer_states(model), optimizer_states(resumed), strict=True):
        assert [state["step"].item() for state in old["state"].values()] == [
            state["step"].item() for state in new["state"].values()
        ]


def test_frames_compressed_in_chunks_written_once(tmp_path: Path) -> None:
    """
    Each checkpoint writes the rows added since the last one; a next frame that is the next row's frame is stored once;
    after the buffer wraps around, all rows again; the buffer reads back exactly.
    """
    model = make_model(buffer_size=60)
    folder = tmp_path / "checkpoint"
    model.learn(25)
    save_checkpoint(model, folder, SETTINGS)
    model.learn(20, reset_num_timesteps=False)
    save_checkpoint(model, folder, SETTINGS)
    info = read_checkpoint(folder)
    assert [(chunk["start"], chunk["end"]) for chunk in info["frame_chunks"]] == [(0, 25), (25, 45)]
    assert sorted(path.name for path in (folder / "frames").iterdir()) == sorted(c["file"] for c in info["frame_chunks"])
    assert {path.name for path in folder.iterdir() if path.is_dir()} == {"45", "frames"}  # the previous one removed
    with np.load(folder / "frames" / info["frame_chunks"][1]["file"]) as chunk:
        # within an episode the next frame is the next row's: stored for the episode ends and the last row only
        assert chunk["next_observations.observation.other"].shape[0] == 3  # rows 29, 39 (episode ends) and 44
        assert chunk["observations.observation"].shape == (20, 1, 3, 40, 40)
    assert_same_buffer(model.replay_buffer, load(folder).replay_buffer, 45)
    # a chunk of one row: the zoo's last checkpoint one row after its periodic one (taken before the step is stored)
    model.learn(1, reset_num_timesteps=False)
    save_checkpoint(model, folder, SETTINGS)
    assert [(chunk["start"], chunk["end"]) for chunk in read_checkpoint(folder)["frame_chunks"]][-1] == (45, 46)
    assert_same_buffer(model.replay_buffer, load(folder).replay_buffer, 46)
    model.learn(29, reset_num_timesteps=False)  # 75 steps in 60 rows: wrapped around
    save_checkpoint(model, folder, SETTINGS)
    info = read_checkpoint(folder)
    assert [(chunk["start"], chunk["end"]) for chunk in info["frame_chunks"]] == [(0, 60)]
    assert_same_buffer(model.replay_buffer, load(folder).replay_buffer, 60)


def test_checkpoints_carry_the_training_time_across_processes(tmp_path: Path) -> None:
    """
    CheckpointEvery records the wall time training took to reach each checkpoint (``training_s``); a resumed run's
    callback starts from its checkpoint's, so a checkpoint after a resume counts both processes; without a known
    earlier time, none is recorded; a plain save_checkpoint records none.
    """
    model, folder = make_model(), tmp_path / "checkpoint"
    first = CheckpointEvery(20, folder, SETTINGS)
    model.learn(45, callback=first)
    after_first = read_checkpoint(folder)
    assert after_first["num_timesteps"] == 40 and 0 < after_first["training_s"] <= first.training_s()
    resumed = load(folder)
    resumed.learn(30, callback=CheckpointEvery(20, folder, SETTINGS, after_first["training_s"]), reset_num_timesteps=False)
    after_second = read_checkpoint(folder)
    assert after_second["num_timesteps"] == 60 and after_second["training_s"] > after_first["training_s"]
    load(folder).learn(20, callback=CheckpointEvery(20, folder, SETTINGS, None), reset_num_timesteps=False)
    assert read_checkpoint(folder)["num_timesteps"] == 80 and "training_s" not in read_checkpoint(folder)
    save_checkpoint(model, folder, SETTINGS)
    assert "training_s" not in read_checkpoint(folder)


def test_resume_bad_input(tmp_path: Path) -> None:
    """No checkpoint, or one of other settings or another format: a clear error naming the problem."""
    with pytest.raises(FileNotFoundError, match=r"no checkpoint in .*empty"):
        load(tmp_path / "empty")
    model = make_model()
    model.learn(25)
    folder = tmp_path / "checkpoint"
    save_checkpoint(model, folder, SETTINGS)
    with pytest.raises(ValueError, match=r"another run \(learning_rate: 0.0003 in the checkpoint, 0.001 now\)"):
        load(folder, {**SETTINGS, "learning_rate": 1e-3})
    with pytest.raises(ValueError, match=r"task: 'image-goal' in the checkpoint, 'other' now"):
        load(folder, {**SETTINGS, "task": "other"})
    info = json.loads((folder / CHECKPOINT_FILE).read_text())
    (folder / CHECKPOINT_FILE).write_text(json.dumps({**info, "format": 99}))
    with pytest.raises(ValueError, match="format 99"):
        load(folder)


def test_a_pilot_buffer_resumes_reading_its_own_rows(tmp_path: Path) -> None:
    """
    PilotHerReplayBuffer (HER + PILoT) checkpointed and resumed: the previous achieved goals its relabelled bonuses read
    are the resumed buffer's own rows, those written after the checkpoint included, not a copy of the buffer saved with
    the checkpoint (which also kept the whole buffer, frames included, a second time in state.pkl).
    """
    model = make_model(replay_buffer_class=PilotHerReplayBuffer)
    model.learn(45)
    save_checkpoint(model, tmp_path / "checkpoint", SETTINGS)
    step_folder = tmp_path / "checkpoint" / "45"
    frames = model.replay_buffer.observations["observation"].nbytes
    assert (step_folder / "state.pkl").stat().st_size < frames
    resumed = load(tmp_path / "checkpoint")
    buffer = resumed.replay_buffer
    assert isinstance(buffer, PilotHerReplayBuffer)
    resumed.learn(30, reset_num_timesteps=False)
    rows = np.arange(buffer.pos)
    stored = buffer.infos[rows, np.zeros_like(rows)][PREVIOUS_ACHIEVED_GOAL]
    np.testing.assert_array_equal(stored, buffer.observations["achieved_goal"][rows, 0])
    assert np.abs(stored[45:]).sum() > 0  # the rows written after the checkpoint
    copy = pickle.loads(pickle.dumps(buffer))  # as SB3's save_replay_buffer and load_replay_buffer do
    np.testing.assert_array_equal(copy.infos[rows, np.zeros_like(rows)][PREVIOUS_ACHIEVED_GOAL], stored)
    assert copy.infos.buffer is copy
