"""
Pixel-only agents for the image tasks: the image encoder (:class:`PixelGoalExtractor`, DrQ's :class:`RandomShift`)
and the SAC policy that trains it from the critic's loss, with an auxiliary goal prediction
(:class:`PixelGoalSACPolicy`). In an RL-Zoo YAML: ``policy: sb3_pilot.pixels.PixelGoalSACPolicy`` (the older path
``sb3_pilot.common.torch_layers.PixelGoalSACPolicy`` names the same class).
"""

from sb3_pilot.pixels.encoder import PixelGoalExtractor, RandomShift
from sb3_pilot.pixels.policies import EncodedObservations, PixelGoalSACPolicy

__all__ = ["EncodedObservations", "PixelGoalExtractor", "PixelGoalSACPolicy", "RandomShift"]
