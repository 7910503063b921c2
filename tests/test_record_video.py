"""``python -m sb3_pilot.experiments.zoo record_video`` / ``record_training``: the zoo's videos of a UDPO agent."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sb3_pilot.experiments import zoo


def run_zoo(*args: str, cwd: Path) -> str:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MUJOCO_GL": "osmesa", "PYOPENGL_PLATFORM": "osmesa"}
    command = [sys.executable, "-m", "sb3_pilot.experiments.zoo", *args]
    result = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return result.stdout


def test_record_video_and_training_of_udpo_on_a_pilot_task(tmp_path: Path) -> None:
    common = ("--algo", "udpo", "--env", "Pilot/Reacher-v0", "-f", "logs")
    small = ("-params", "learning_starts:100", "n_envs:1", "batch_size:64")
    run_zoo("train", *common, "--num-threads", "1", "-n", "200", "--seed", "0", "--eval-freq", "-1", *small, cwd=tmp_path)
    out = run_zoo("record_video", *common, "-n", "20", "-o", "videos", cwd=tmp_path)
    videos = list((tmp_path / "videos").glob("final-model-udpo-Pilot-Reacher-v0-*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000, out
    assert videos[0].read_bytes()[4:8] == b"ftyp"  # an MP4 file
    # the zoo's own record_training calls `python -m rl_zoo3.record_video`, which knows no udpo: here it works
    out = run_zoo("record_training", *common, "-n", "20", "-o", "training", cwd=tmp_path)
    training = tmp_path / "training" / "training.mp4"
    assert training.is_file() and training.read_bytes()[4:8] == b"ftyp", out


def test_record_training_needs_ffmpeg(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")

    def no_binary() -> str:
        raise RuntimeError("No ffmpeg exe could be found.")

    monkeypatch.setattr(zoo.shutil, "which", lambda name: None)
    monkeypatch.setattr(imageio_ffmpeg, "get_ffmpeg_exe", no_binary)
    with pytest.raises(SystemExit, match="ffmpeg command, which is not on PATH"):
        zoo.main(["record_training", "--algo", "udpo", "--env", "Pilot/Reacher-v0", "-f", str(tmp_path)])


def test_guided_ant_maze_gif(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The docs' GIF command, on a short episode: the shipped controller and planner, rendered frames with landmarks."""
    from PIL import Image

    from sb3_pilot.experiments import guided_video

    output = tmp_path / "guided.gif"
    guided_video.main(["--max-steps", "12", "--any", "--size", "64", "--stride", "4", "--output", str(output)])
    assert "reset seed 0" in capsys.readouterr().out
    with Image.open(output) as gif:
        assert gif.size == (64, 64) and gif.n_frames >= 3  # steps 0, 4, 8, then the held last frame
        gif.seek(1)
        second = np.asarray(gif.convert("RGB"), dtype=float)
    green = (second[..., 1] > 150) & (second[..., 0] < 100) & (second[..., 2] < 100)
    assert green.any()  # the landmark's marker is drawn


def test_record_video_of_a_task_that_does_not_render() -> None:
    with pytest.raises(SystemExit, match=r"renders rgb_array frames, Pilot/Maze2D-v0 does not\. .*Pilot/Reacher-v0"):
        zoo.main(["record_video", "--algo", "udpo", "--env", "Pilot/Maze2D-v0", "-f", "logs"])
