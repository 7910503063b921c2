"""What the three stages share: Gaussian log-likelihoods, argument checks and small torch helpers; and the features
extractors that an RL-Zoo YAML names (:mod:`sb3_pilot.common.torch_layers`; the image policy's home is
:mod:`sb3_pilot.pixels`, whose names stay importable from here)."""

from sb3_pilot.common.torch_layers import GoalRelativeExtractor, PixelGoalExtractor, PixelGoalSACPolicy

__all__ = ["GoalRelativeExtractor", "PixelGoalExtractor", "PixelGoalSACPolicy"]
