"""
MEGA (Pitis et al. 2020, "Maximum Entropy Gain Exploration for Long Horizon Multi-goal RL"): training episodes pursue
a past achieved goal of low density instead of the env's goal. :class:`MegaGoalWrapper` puts the behaviour goals into
the training env, :class:`MegaCallback` chooses them; :class:`KernelDensity` is the density model.
"""

from sb3_pilot.baselines.mega.density import KernelDensity
from sb3_pilot.baselines.mega.goal_wrapper import MegaGoalWrapper
from sb3_pilot.baselines.mega.mega import MegaCallback

__all__ = ["KernelDensity", "MegaCallback", "MegaGoalWrapper"]
