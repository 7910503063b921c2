"""The walled maze's landmark check (benchmarks/wall_landmarks.py) on scripted planners and teachers."""

from __future__ import annotations

import numpy as np
import torch as th

from benchmarks.wall_landmarks import grid_pairs, grid_positions, measure_planner, teacher_steps
from sb3_pilot.distill import GoalPlanner
from sb3_pilot.envs import WallMaze, register_envs

register_envs()
MAZE = WallMaze()
STEP = 0.15
#: Above the wall's top (y < 0): where the scripted detour heads first
WAYPOINT = th.tensor([0.0, 0.3])


def detour_step(achieved: th.Tensor, desired: th.Tensor) -> th.Tensor:
    """A move of at most ``STEP`` towards the goal, or first towards ``WAYPOINT`` from the other side of ``x = 0``
    (beyond 0.01 of it) when the point or the goal lies under it."""
    (x, y), (goal_x, goal_y) = achieved.T, desired.T
    across = (x * goal_x < 0) & (x.abs() > 0.01) & ((y < WAYPOINT[1]) | (goal_y < WAYPOINT[1]))
    delta = th.where(across[:, None], WAYPOINT - achieved, desired - achieved)
    return delta * th.clamp(STEP / th.linalg.norm(delta, dim=1, keepdim=True).clamp_min(1e-9), max=1.0)


class DetourPlanner(GoalPlanner):
    """Plans :func:`detour_step`: round the wall's top, never into it."""

    def forward(self, achieved_goal: th.Tensor, desired_goal: th.Tensor, deterministic: bool = True) -> th.Tensor:
        return achieved_goal + detour_step(achieved_goal, desired_goal)


def straight_planner() -> GoalPlanner:
    """A planner whose landmark is halfway to the goal: through the wall when the goal is across it."""
    planner = GoalPlanner(2, net_arch=[], metadata={"source_task": "Pilot/WallMaze2D-v0"})
    with th.no_grad():
        weight = planner.net[0].weight
        weight.zero_()
        planner.net[0].bias.zero_()
        weight[0, 0], weight[0, 2], weight[1, 1], weight[1, 3] = -0.5, 0.5, -0.5, 0.5
    return planner


class ScriptedTeacher:
    """``predict`` as an SB3 model's: the action that moves the point by :func:`detour_step` (or straight at the goal)."""

    def __init__(self, detour: bool):
        self.detour = detour

    def predict(self, observation: dict[str, np.ndarray], deterministic: bool = True) -> tuple[np.ndarray, None]:
        achieved, desired = (th.as_tensor(observation[key]) for key in ("achieved_goal", "desired_goal"))
        move = detour_step(achieved, desired) if self.detour else desired - achieved
        return np.clip(move.numpy() / 0.2, -1.0, 1.0), None  # Pilot/WallMaze2D-v0 moves 0.2 per unit of action


def test_grid_and_classes() -> None:
    positions = grid_positions(MAZE, 5)  # x, y in {-0.8, -0.4, 0, 0.4, 0.8}: not x = 0 below the gap, nor (0, 0)
    assert len(positions) == 22 and MAZE.off_wall(positions).all()
    _, _, classes = grid_pairs(MAZE, positions)
    # below the gap: 2 rows x 4 columns; across: 8 starts x 4 goals, same side: 8 x 3
    assert [(classes == name).sum() for name in ("across", "same side", "above")] == [32, 24, 22 * 21 - 56]


def test_straight_landmarks_cut_through_the_wall() -> None:
    results = measure_planner(straight_planner(), MAZE, grid_positions(MAZE, 5), horizon=10, success_distance=0.1)
    across = results["across"]
    # halfway between mirrored positions lies on x = 0 below the gap: 2 mirrored goals for each of the 8 starts
    assert across["one_step"]["in_wall"] == 16 and across["chained"]["in_wall"] == 16
    assert across["one_step"]["outside"] == 0 and 0.0 < across["one_step"]["depth"] <= MAZE.wall_half_width
    assert across["through_gap"] == 0.0 and across["through_wall"] == 1.0
    assert results["same side"]["chained"]["in_wall"] == 0 and results["same side"]["reached"] == 1.0


def test_detour_landmarks_go_round_the_wall() -> None:
    planner = DetourPlanner(2, net_arch=[], metadata={"source_task": "Pilot/WallMaze2D-v0"})
    results = measure_planner(planner, MAZE, grid_positions(MAZE, 5), horizon=30, success_distance=0.1)
    for result in results.values():
        assert result["one_step"]["in_wall"] == result["chained"]["in_wall"] == 0
        assert result["chained"]["outside"] == 0 and result["chained"]["depth"] == 0.0
        assert result["reached"] == 1.0 and 0.1 < result["planned_step"] <= STEP + 1e-6
    assert results["across"]["through_gap"] == 1.0 and results["across"]["through_wall"] == 0.0


def test_teacher_real_step_and_success() -> None:
    positions = grid_positions(MAZE, 4)  # x, y in {-0.8, -0.27, 0.27, 0.8}
    detour = teacher_steps(ScriptedTeacher(detour=True), MAZE, positions)
    assert detour["success"] == {"across": 1.0, "same side": 1.0, "above": 1.0}
    assert 0.1 < detour["real_step"] <= STEP + 1e-6
    straight = teacher_steps(ScriptedTeacher(detour=False), MAZE, positions)
    assert straight["success"]["across"] == 0.0 and straight["success"]["same side"] == 1.0  # stopped by the wall
