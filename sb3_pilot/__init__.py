"""
sb3-pilot: PILoT (Planning Immediate Landmarks of Targets) for Stable-Baselines3.

The library follows the paper's three stages: :mod:`sb3_pilot.udpo` (pre-training), :mod:`sb3_pilot.distill`
(distillation) and :mod:`sb3_pilot.transfer` (transfer), on :mod:`sb3_pilot.common`; :mod:`sb3_pilot.envs` holds the
paper's tasks. :mod:`sb3_pilot.experiments` (the RL-Zoo entry, challenges, plots, statistics, demo) builds on the
library and is never imported by it.
"""

from sb3_pilot.distill import GoalMap, GoalPlanner, distill_goal_planner, share_goal_space
from sb3_pilot.envs import register_envs
from sb3_pilot.transfer import (
    LandmarkGuidance,
    PilotBonusWrapper,
    PilotHerReplayBuffer,
    StatePlannerTransferCallback,
    load_planner_from,
)
from sb3_pilot.udpo import UDPO
from sb3_pilot.version import __version__

register_envs()  # the Pilot/...-v0 tasks (also what `rl_zoo3 --gym-packages sb3_pilot` relies on)

__all__ = [
    "UDPO",
    "GoalMap",
    "GoalPlanner",
    "LandmarkGuidance",
    "PilotBonusWrapper",
    "PilotHerReplayBuffer",
    "StatePlannerTransferCallback",
    "__version__",
    "distill_goal_planner",
    "load_planner_from",
    "register_envs",
    "share_goal_space",
]
