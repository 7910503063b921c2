"""
UDPO's lambda (``planner_coef``) on the wall maze: the wall test's teacher (``tests/maze_envs.py``'s ``train_udpo``
construction, 20k steps) with each lambda and seed, evaluated every 2k steps on the cross-wall goals of
``tests/wall_maze_teacher.py``'s four start/goal pairs (deterministic once + sampled 5 times: 24 episodes) and on
``wall_detour_end``'s pair (the test's). The evaluation restores torch's and NumPy's generators, so the run is the one
``train_udpo`` makes (checked: the 20k ``wall_detour_end`` equals the test's). One JSON line per run.

    OMP_NUM_THREADS=1 python zoo_runs/sources/lambda/wall_maze.py --coefs 0 1e-3 1e-2 --seeds 0 1 2 3 > OUT.jsonl
"""

import argparse
import json
import random
import sys
import time
from pathlib import Path

import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tests"))
from maze_envs import SMALL_HER_SETTINGS, UDPO_SETTINGS, WallMazeEnv, wall_detour_end
from wall_maze_teacher import cross_wall_successes

from sb3_pilot import UDPO


class CrossWallEval(BaseCallback):
    """Every ``every`` steps: cross-wall successes (deterministic /4, sampled /20) and the test pair's outcome."""

    def __init__(self, every: int):
        super().__init__()
        self.every, self.rows = every, []

    def _on_step(self) -> bool:
        if self.num_timesteps % self.every == 0:
            states = th.get_rng_state(), np.random.get_state(), random.getstate()
            env = WallMazeEnv()
            det = cross_wall_successes(self.model, env, deterministic=True, repeats=1)
            sampled = cross_wall_successes(self.model, env, deterministic=False, repeats=5)
            reached, end = wall_detour_end(self.model)
            th.set_rng_state(states[0]), np.random.set_state(states[1]), random.setstate(states[2])
            self.rows.append([self.num_timesteps, det, sampled, bool(reached), [round(float(v), 3) for v in end]])
        return True


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--coefs", type=float, nargs="+", default=[0.0, 1e-3, 1e-2])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--every", type=int, default=2000)
    args = parser.parse_args()
    for coef in args.coefs:
        for seed in args.seeds:
            start = time.time()
            model = UDPO(
                "MultiInputPolicy",
                Monitor(WallMazeEnv()),
                **SMALL_HER_SETTINGS,
                **UDPO_SETTINGS,
                planner_coef=coef,
                plan_target="buffer",
                seed=seed,
            )
            callback = CrossWallEval(args.every)
            model.learn(args.steps, callback=callback)
            reached, end = wall_detour_end(model)
            row = {"planner_coef": coef, "seed": seed, "steps": args.steps, "detour_end": [bool(reached), end.tolist()]}
            row.update(evals=callback.rows, wall_time_s=round(time.time() - start, 1))
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
