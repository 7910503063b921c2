"""Gradient-step time of UDPO with each entropy_term, alternating in one process (walled maze, 64x64 and 256x256).
Usage: OMP_NUM_THREADS=1 python zoo_runs/sources/lambda/entropy_probes/step_cost.py > step_cost.txt"""

import sys
import time

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[4] / "tests"))
import torch as th
from maze_envs import SMALL_HER_SETTINGS, UDPO_SETTINGS, WallMazeEnv

from sb3_pilot import UDPO

th.set_num_threads(1)
for arch in ([64, 64], [256, 256]):
    m = UDPO(
        "MultiInputPolicy",
        WallMazeEnv(),
        **{**SMALL_HER_SETTINGS, "learning_starts": 2000, "policy_kwargs": {"net_arch": arch}},
        **UDPO_SETTINGS,
        seed=0,
    )
    m.learn(2000)
    m._n_updates = 1
    res = {"inverse_dynamics": [], "linearised": []}
    for _rep in range(5):
        for name in res:
            m.policy.entropy_term = name
            t = time.perf_counter()
            m.train(100, 256)
            res[name].append((time.perf_counter() - t) * 10)
    med = {k: sorted(v)[2] for k, v in res.items()}
    print(
        arch, {k: round(v, 2) for k, v in med.items()}, "ms/step, ratio", round(med["linearised"] / med["inverse_dynamics"], 2)
    )
