"""The challenge runner's display: env steps read from a stage's progress.csv, the live table and the plain lines."""

from __future__ import annotations

import io
import os
import re
import time
from pathlib import Path

import pytest
from rich.console import Console

from sb3_pilot.experiments.challenges.display import RunDisplay, StageProgress, clock, render, stage_name, steps_done
from sb3_pilot.experiments.challenges.stages import PROGRESS_CSV


def write_progress(stage_dir: Path, rows: list[int], written_at: float) -> None:
    """A progress.csv as SB3's logger writes it (the env steps column among others), last written at ``written_at``."""
    lines = ["rollout/ep_rew_mean,time/total_timesteps,train/actor_loss"]
    lines += [f"-1.5,{steps},0.25" for steps in rows]
    (stage_dir / PROGRESS_CSV).write_text("\n".join(lines) + "\n")
    os.utime(stage_dir / PROGRESS_CSV, (written_at, written_at))


def test_steps_done(tmp_path: Path) -> None:
    assert steps_done(tmp_path) is None  # not written yet
    write_progress(tmp_path, [], 1000.0)
    assert steps_done(tmp_path) is None  # the header alone
    write_progress(tmp_path, list(range(100, 100_001, 100)), 1000.0)  # longer than the tail it reads
    assert steps_done(tmp_path) == (1000.0, 100_000)
    with (tmp_path / PROGRESS_CSV).open("a") as file:
        file.write("-1.4,100")  # a row being written: the last complete one counts
    assert steps_done(tmp_path)[1] == 100_000
    (tmp_path / PROGRESS_CSV).write_text("a,b\n1,2\n")  # no env steps column
    assert steps_done(tmp_path) is None


def test_eta_from_the_pace_between_rows(tmp_path: Path) -> None:
    stage = StageProgress("seed_0/her", "sac on Pilot/Maze2DCar-v0", tmp_path, total=20_000, start=0.0)
    assert stage.eta(10.0) is None and stage.steps is None  # nothing read yet
    stage.first, stage.last = (20.0, 2000), (90.0, 9000)  # 100 steps/s between the two rows
    assert stage.eta(100.0) == pytest.approx(11_000 / 100 - 10)
    stage.first = stage.last  # one row: the pace since the start
    assert stage.eta(90.0) == pytest.approx(11_000 / 100)
    stage.last = (200.0, 20_000)
    assert stage.eta(300.0) == 0.0
    assert StageProgress("seed_0/distill", "distil", tmp_path, total=None, start=0.0).eta(5.0) is None
    assert clock(3725) == "1:02:05" and clock(None) == "-" and stage_name("seed_3/pilot_disp") == "seed 3 pilot_disp"


def test_render_shows_each_running_stage(tmp_path: Path) -> None:
    training = StageProgress("seed_0/her", "sac on Pilot/Maze2DCar-v0", tmp_path, 20_000, 0.0, (20.0, 2000), (90.0, 9000))
    distill = StageProgress("seed_1/distill", "distil the goal planner of source", tmp_path, None, 95.0)
    console = Console(file=io.StringIO(), width=150, color_system=None)
    console.print(render("maze-car cpu", 3, 10, 123.0, [training, distill], now=100.0))
    text = console.file.getvalue()
    assert "maze-car cpu: 3/10 stages done, 0:02:03" in text
    her = next(line for line in text.splitlines() if "seed_0/her" in line)
    assert "sac on Pilot/Maze2DCar-v0" in her and "9000/20000" in her and "0:01:40" in her  # elapsed and ETA
    assert "━" in her  # the bar
    distill_row = next(line for line in text.splitlines() if "seed_1/distill" in line)
    assert " - " in distill_row and "0:00:05" in distill_row


def test_plain_lines(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Not a terminal: a line per event, no escape codes, and a line of env steps for a stage not reported for long."""
    write_progress(tmp_path, [500, 1000], time.time())
    with RunDisplay("tiny smoke", total=3, plain_every=0.0) as display:
        display.skipped("seed 0 source: done (12 s), skipped")
        display.started("seed_0/her", "sac on Pilot/Maze2DCar-v0, 2000 env steps", tmp_path, 2000)
        display.started("seed_0/distill", "distil the goal planner of source", tmp_path, None)
        display.tick()
        display.finished("seed_0/her", 61.0)
    lines = capsys.readouterr().out.splitlines()
    assert not any("\x1b" in line for line in lines)
    parsed = [re.fullmatch(r"\[tiny smoke (\d)/3 \d+s\]? (.*)", line).groups() for line in lines]
    assert [done for done, _ in parsed] == ["1"] * 7 + ["2"] * 2  # [challenge budget done/total elapsed]
    assert [text for _, text in parsed] == [
        "seed 0 source: done (12 s), skipped",
        "seed 0 her: sac on Pilot/Maze2DCar-v0, 2000 env steps",
        "running: seed_0/her]",
        "seed 0 distill: distil the goal planner of source",
        "running: seed_0/her, seed_0/distill]",
        "seed 0 her: 1000/2000 env steps (50%), 0:00:00 elapsed, ETA -",  # its last row predates its start: no pace yet
        "seed 0 distill: 0:00:00 elapsed",
        "seed 0 her: finished in 61 s",
        "running: seed_0/distill]",
    ]


def test_live_display_prints_lines_above_the_table(tmp_path: Path) -> None:
    """On a terminal: the event lines, and the table redrawn while stages run (gone once the run ends)."""
    write_progress(tmp_path, [700], time.time())
    console = Console(file=io.StringIO(), width=150, force_terminal=True, color_system=None)
    with RunDisplay("tiny smoke", total=2, live=True, console=console) as display:
        display.started("seed_0/her", "sac on Pilot/Maze2DCar-v0, 2000 env steps", tmp_path, 2000)
        display.tick()
        text = console.file.getvalue()
        assert "seed 0 her: sac on Pilot/Maze2DCar-v0, 2000 env steps" in text
        assert "tiny smoke: 0/2 stages done" in text and "700/2000" in text
        assert "running:" not in text  # the table says it
        display.finished("seed_0/her", 3.0)
        after = console.file.getvalue().split("seed 0 her: finished in 3 s")[1]
        assert "tiny smoke: 1/2 stages done" in after and "seed_0/her" not in after  # the table as it is now
