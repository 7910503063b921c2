"""``python -m sb3_pilot.experiments.guide``: the guidance of a trained controller chosen from its run, the planner and the
task, measured beside the controller unguided; what it refuses before any episode."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import pytest

from sb3_pilot.distill import GoalPlanner
from sb3_pilot.experiments import guide
from sb3_pilot.experiments.challenges.definitions import SHIPPED_V1_DIR, UMAZE_SHIPPED_DIR
from sb3_pilot.transfer import choose_guidance, success_radius

CONTROLLER = SHIPPED_V1_DIR / "ant_v1_controller_seed1_sac_200k.zip"
PLANNER = SHIPPED_V1_DIR / "maze2d_planner_seed1.pt"


def test_guide_the_shipped_v1_controller(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The lead from the controller's training goals (0.9 x 3), k and the switch from the planner and the task's radius."""
    assert guide.trained_goal_range(CONTROLLER) == (0.5, 3.0)
    out = tmp_path / "guide.json"
    argv = ["--controller", str(CONTROLLER), "--planner", str(PLANNER), "--env", "Pilot/AntMaze-v1", "--episodes", "1"]
    summary = guide.main([*argv, "--out", str(out)])
    settings = choose_guidance(gym.make("Pilot/AntMaze-v1"), PLANNER, 2.7)
    assert summary["lead"] == pytest.approx(2.7) and summary["horizon"] == settings.horizon == 5
    assert summary["switch_distance"] == pytest.approx(1.0 + settings.goal_bias)
    assert summary["success_radius"] == 1.0 == success_radius(gym.make("Pilot/AntMaze-v1"))
    assert json.loads(out.read_text())["guided_success"] == summary["guided_success"]
    assert len(summary["results"]["guided"]["episodes"][0]["landmarks"]) == 501  # the whole episode's landmarks
    assert "landmarks" not in summary["results"]["unguided"]["episodes"][0]
    printed = capsys.readouterr().out
    assert "k = 5" in printed and "guided: success" in printed and "unguided: success" in printed


def test_guide_refuses_before_any_episode(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["--controller", str(CONTROLLER), "--planner", str(PLANNER), "--env"]
    stays = GoalPlanner.load(PLANNER)
    holdout = stays.metadata["holdout"]
    stays.metadata["holdout"] = {**holdout, "landmark_distance": holdout["landmark_distance_untrained"]}
    stays.save(tmp_path / "stays.pt")
    cases = [
        ([*base, "Pilot/AntMaze-v9"], "no registered Gymnasium task"),
        ([*base[:3], str(tmp_path / "stays.pt"), "--env", "Pilot/AntMaze-v1"], "nothing beyond staying put"),
        ([*base, "AntMaze_UMaze-v5"], "goal"),  # a planner of Maze2D on gymnasium-robotics' maze, no goal map declared
        (
            [*base[:1], str(UMAZE_SHIPPED_DIR / "antmaze_open_controller_seed0_sac_300k.zip"), *base[2:], "Pilot/AntMaze-v0"],
            "--lead",
        ),
    ]
    for argv, message in cases:
        with pytest.raises(SystemExit):
            guide.main(argv)
        assert message in capsys.readouterr().err
