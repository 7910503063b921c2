from sb3_pilot.udpo.policies import MlpPolicy, MultiInputPolicy, UDPOPolicy
from sb3_pilot.udpo.udpo import UDPO

__all__ = ["UDPO", "MlpPolicy", "MultiInputPolicy", "UDPOPolicy"]
