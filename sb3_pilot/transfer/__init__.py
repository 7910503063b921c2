"""
Transfer (paper section 3.3): the reward bonus of a distilled goal planner (HER + PILoT), the state planner reused
under another action space, and zero-shot landmark guidance of a pre-trained controller.
"""

from sb3_pilot.transfer.bonus import SIMILARITIES, PilotBonusWrapper, PilotHerReplayBuffer
from sb3_pilot.transfer.guidance import (
    GuidanceSettings,
    LandmarkGuidance,
    choose_guidance,
    goal_bias,
    horizon_for_lead,
    landmark_leads,
    success_radius,
)
from sb3_pilot.transfer.state_planner import StatePlannerTransferCallback, load_planner_from

__all__ = [
    "SIMILARITIES",
    "GuidanceSettings",
    "LandmarkGuidance",
    "PilotBonusWrapper",
    "PilotHerReplayBuffer",
    "StatePlannerTransferCallback",
    "choose_guidance",
    "goal_bias",
    "horizon_for_lead",
    "landmark_leads",
    "load_planner_from",
    "success_radius",
]
