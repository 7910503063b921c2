"""sb3-pilot: PILoT (Planning Immediate Landmarks of Targets) for Stable-Baselines3."""

from sb3_pilot.udpo import UDPO
from sb3_pilot.version import __version__

__all__ = ["UDPO", "__version__"]
