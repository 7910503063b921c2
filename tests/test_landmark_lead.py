"""The landmark lead (benchmarks/landmark_lead.py) of a scripted planner whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest
import torch as th

from benchmarks.landmark_lead import far_pairs, leads, main
from sb3_pilot.distill import GoalPlanner
from sb3_pilot.envs import umaze_cell_to_xy

STEP = 0.1


class StraightPlanner(GoalPlanner):
    """Plans a step of ``STEP`` straight towards the goal."""

    def forward(self, achieved_goal: th.Tensor, desired_goal: th.Tensor, deterministic: bool = True) -> th.Tensor:
        delta = desired_goal - achieved_goal
        return achieved_goal + STEP * delta / th.linalg.norm(delta, dim=1, keepdim=True)


def test_far_pairs_are_in_the_planners_coordinates() -> None:
    starts, goals = far_pairs(50, scale=4.0)
    assert np.abs(starts - umaze_cell_to_xy((1, 1)) / 4).max() <= 0.25  # gymnasium-robotics' noise, 1 AntMaze unit
    assert np.abs(goals - umaze_cell_to_xy((3, 1)) / 4).max() <= 0.25


def test_lead_of_a_straight_planner() -> None:
    """k steps of STEP planner units are k * STEP * scale target units ahead (the ends are 8 apart: no overshoot)."""
    result = leads(StraightPlanner(2, net_arch=[]), [1, 5, 10], scale=4.0, n=20)
    assert result["median"] == pytest.approx([0.4, 2.0, 4.0], abs=1e-5)
    assert result["q25"] == pytest.approx(result["q75"], abs=1e-5) and result["first_step"] == pytest.approx([0.4], abs=1e-5)


def test_bad_input(tmp_path) -> None:
    with pytest.raises(SystemExit):
        main([str(tmp_path / "missing.pt")])
    with pytest.raises(SystemExit):
        main([str(tmp_path / "missing.pt"), "--scale", "0"])
