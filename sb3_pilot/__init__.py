"""sb3-pilot: PILoT (Planning Immediate Landmarks of Targets) for Stable-Baselines3."""

from sb3_pilot.distill import distill_goal_planner
from sb3_pilot.envs import register_envs
from sb3_pilot.planner import GoalPlanner, share_goal_space
from sb3_pilot.transfer import load_planner_from
from sb3_pilot.udpo import UDPO
from sb3_pilot.version import __version__
from sb3_pilot.wrappers import LandmarkGuidance, PilotBonusWrapper, PilotHerReplayBuffer

register_envs()  # the Pilot/...-v0 tasks (also what `rl_zoo3 --gym-packages sb3_pilot` relies on)

__all__ = [
    "UDPO",
    "GoalPlanner",
    "LandmarkGuidance",
    "PilotBonusWrapper",
    "PilotHerReplayBuffer",
    "__version__",
    "distill_goal_planner",
    "load_planner_from",
    "register_envs",
    "share_goal_space",
]
