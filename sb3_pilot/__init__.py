"""sb3-pilot: PILoT (Planning Immediate Landmarks of Targets) for Stable-Baselines3."""

from sb3_pilot.envs import register_envs
from sb3_pilot.udpo import UDPO
from sb3_pilot.version import __version__

register_envs()  # the Pilot/...-v0 tasks (also what `rl_zoo3 --gym-packages sb3_pilot` relies on)

__all__ = ["UDPO", "__version__", "register_envs"]
