"""What the three stages share: Gaussian log-likelihoods, argument checks and small torch helpers; and the features
extractors and image policy that an RL-Zoo YAML names (:mod:`sb3_pilot.common.torch_layers`)."""

from sb3_pilot.common.torch_layers import GoalRelativeExtractor, PixelGoalExtractor, PixelGoalSACPolicy

__all__ = ["GoalRelativeExtractor", "PixelGoalExtractor", "PixelGoalSACPolicy"]
