"""Distillation (paper section 3.2): the goal planner ``f(g' | g, g_target)`` distilled from UDPO's state planner."""

from sb3_pilot.distill.distill import distill_goal_planner
from sb3_pilot.distill.goal_map import GoalMap
from sb3_pilot.distill.goal_planner import GoalPlanner, goal_map_between, share_goal_space, shares_goal_space

__all__ = ["GoalMap", "GoalPlanner", "distill_goal_planner", "goal_map_between", "share_goal_space", "shares_goal_space"]
