"""Rough edges found by following the docs: each refused (or warned about) with a message naming the problem."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from goal_envs import PointGoalEnv
from stable_baselines3 import HerReplayBuffer

from sb3_pilot import UDPO, GoalPlanner, distill_goal_planner
from sb3_pilot.experiments.challenges import run_challenge
from sb3_pilot.experiments.challenges.__main__ import main as challenges_main

ZOO_RUNS = Path(__file__).resolve().parents[1] / "zoo_runs"
#: a path from the file system's root, alone or inside a command line (``'folder': '/home/...'``)
ABSOLUTE_PATH = re.compile(r"(^|[\s'\"=:,(\[{])/[A-Za-z]")


def test_challenge_with_no_seeds_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--seeds 0`` (read as "seed 0") used to run nothing and end in ``KeyError: 'challenge'`` on an empty summary."""
    with pytest.raises(SystemExit):
        challenges_main(["high-dim-action", "--seeds", "0", "--root", str(tmp_path)])
    assert "a count of seeds is at least 1" in capsys.readouterr().err
    for bad, message in [
        ("3-1", "goes down"),
        ("1,1", "twice"),
        ("0-2,2", "twice"),
        ("a", "takes a count"),
        ("-1", "takes a count"),
    ]:
        with pytest.raises(SystemExit):
            challenges_main(["high-dim-action", "--seeds", bad, "--root", str(tmp_path)])
        assert message in capsys.readouterr().err
    with pytest.raises(ValueError, match="seeds is empty"):
        run_challenge("high-dim-action", seeds=[], root=tmp_path)
    with pytest.raises(ValueError, match="repeated"):
        run_challenge("high-dim-action", seeds=[0, 0], root=tmp_path)
    assert not any(tmp_path.iterdir())  # refused before any work


def test_distilling_an_untrained_teacher() -> None:
    with pytest.raises(ValueError, match="0 env steps"):
        distill_goal_planner(UDPO("MultiInputPolicy", PointGoalEnv(), replay_buffer_class=HerReplayBuffer))
    teacher = UDPO("MultiInputPolicy", PointGoalEnv(), replay_buffer_class=HerReplayBuffer, learning_starts=100)
    teacher.learn(50)
    with pytest.warns(UserWarning, match="no gradient step"):
        kwargs = {"n_samples": 300, "gradient_steps": 2, "batch_size": 32, "net_arch": [8]}
        planner = distill_goal_planner(teacher, **kwargs, allow_unsuccessful_teacher=True)
    assert planner.metadata["teacher_num_timesteps"] == 50


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_planner_refuses_non_finite_goals(bad: float) -> None:
    planner = GoalPlanner(2, net_arch=[8], metadata={"source_task": "PointGoalEnv"})
    good = np.zeros(2, dtype=np.float32)
    with pytest.raises(ValueError, match="achieved_goal holds NaN or infinite values in 1 of its 1 goals"):
        planner.predict(np.array([bad, 0.0]), good)
    with pytest.raises(ValueError, match="desired_goal holds NaN or infinite values in 1 of its 3 goals"):
        planner.plan(np.zeros((3, 2)), np.array([[0.0, 0.0], [0.0, bad], [1.0, 1.0]]), horizon=2)
    assert np.isfinite(planner.plan(good, good, horizon=2)).all()


def strings(value: Any) -> list[str]:
    """Every string inside a JSON value."""
    if isinstance(value, str):
        return [value]
    items = value.values() if isinstance(value, dict) else value if isinstance(value, list) else []
    return [text for item in items for text in strings(item)]


def test_shipped_summaries_hold_no_absolute_paths() -> None:
    """Paths in the committed summaries are written ``<run>/...`` or ``<repo>/...``: they hold on any machine."""
    summaries = sorted(ZOO_RUNS.glob("*/summary.json"))
    assert summaries
    for summary in summaries:
        texts = strings(json.loads(summary.read_text()))
        absolute = [text for text in texts if ABSOLUTE_PATH.search(text)]
        assert not absolute, f"{summary}: {absolute[:3]}"
