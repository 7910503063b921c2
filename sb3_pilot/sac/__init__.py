from sb3_pilot.sac.policies import CnnPolicy, LeanSACPolicy, MlpPolicy, MultiInputPolicy
from sb3_pilot.sac.sac import LeanSAC

__all__ = ["CnnPolicy", "LeanSAC", "LeanSACPolicy", "MlpPolicy", "MultiInputPolicy"]
