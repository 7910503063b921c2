"""
The paper's comparison methods that Stable-Baselines3 lacks, as SB3 parts: :mod:`sb3_pilot.baselines.mega` (MEGA,
Pitis et al. 2020). HIGL and Contrastive RL are not provided.
"""

from sb3_pilot.baselines.mega import KernelDensity, MegaCallback, MegaGoalWrapper

__all__ = ["KernelDensity", "MegaCallback", "MegaGoalWrapper"]
