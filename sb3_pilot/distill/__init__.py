"""Distillation (paper section 3.2): the goal planner ``f(g' | g, g_target)`` distilled from a goal-reaching teacher."""

from sb3_pilot.distill.distill import distill_goal_planner
from sb3_pilot.distill.goal_map import GoalMap
from sb3_pilot.distill.goal_planner import (
    GoalPlanner,
    env_goal_space,
    goal_map_between,
    share_goal_space,
    shares_goal_space,
)
from sb3_pilot.distill.teacher import load_teacher

__all__ = [
    "GoalMap",
    "GoalPlanner",
    "distill_goal_planner",
    "env_goal_space",
    "goal_map_between",
    "load_teacher",
    "share_goal_space",
    "shares_goal_space",
]
