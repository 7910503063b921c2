"""
The learnt entropy temperature on the walled maze (seed 0, the wall test's settings): SB3's SAC + HER, UDPO (lambda
1e-3) and UDPO with Gaussian action noise 0.2, read every 2000 steps up to 8000.

    OMP_NUM_THREADS=1 python zoo_runs/sources/lambda/temperature_probe.py
"""

import sys
from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.noise import NormalActionNoise

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tests"))
from maze_envs import SMALL_HER_SETTINGS, UDPO_SETTINGS, WallMazeEnv

from sb3_pilot import UDPO

if __name__ == "__main__":
    th.set_num_threads(1)
    udpo = {**UDPO_SETTINGS, "planner_coef": 1e-3}
    noise = NormalActionNoise(np.zeros(2), 0.2 * np.ones(2))
    for name, algo, kwargs in (
        ("SAC+HER", SAC, {}),
        ("UDPO", UDPO, udpo),
        ("UDPO, noise 0.2", UDPO, {**udpo, "action_noise": noise}),
    ):
        model = algo("MultiInputPolicy", Monitor(WallMazeEnv()), **SMALL_HER_SETTINGS, **kwargs, seed=0)
        temperatures = []
        for _ in range(4):
            model.learn(2000, reset_num_timesteps=False)
            temperatures.append(f"{model.log_ent_coef.exp().item():.3f}")
        print(f"{name}: temperature at 2k / 4k / 6k / 8k steps: {' / '.join(temperatures)}", flush=True)
