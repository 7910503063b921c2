"""
UDPO's lambda (``planner_coef``) on the wall maze: the wall test's teacher (``tests/maze_envs.py``'s ``train_udpo``
construction, 20k steps) with each lambda and seed, evaluated every 2k steps on the cross-wall goals of
``tests/wall_maze_teacher.py``'s four start/goal pairs (deterministic once + sampled 5 times: 24 episodes) and on
``wall_detour_end``'s pair (the test's). The evaluation restores torch's and NumPy's generators, so the run is the one
``train_udpo`` makes (checked: the line's ``detour_end``, after the last gradient step, equals the test's; the 20k
checkpoint comes one gradient step earlier). One JSON line per run. ``--algo sac``
trains SB3's SAC + HER with the same settings (``SMALL_HER_SETTINGS``) instead, the baseline; ``--jobs`` runs that
many trainings side by side (one process each, one torch thread).

    OMP_NUM_THREADS=1 python zoo_runs/sources/lambda/wall_maze.py --coefs 0 1e-3 1e-2 --seeds 0 1 2 3 > OUT.jsonl
    OMP_NUM_THREADS=1 python zoo_runs/sources/lambda/wall_maze.py --algo udpo sac --coefs 1e-3 --seeds 0 1 --jobs 4
"""

import argparse
import itertools
import json
import multiprocessing
import random
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch as th
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.noise import NormalActionNoise

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "tests"))
from maze_envs import SMALL_HER_SETTINGS, UDPO_SETTINGS, WallMazeEnv, wall_detour_end
from wall_maze_teacher import cross_wall_successes

from sb3_pilot import UDPO

#: UDPO's arguments as the wall test's teacher has them (``train_udpo``), and no action noise
DEFAULTS: dict[str, Any] = {
    **UDPO_SETTINGS,
    "plan_target": "buffer",
    "entropy_term": "inverse_dynamics",
    "ent_coef": "auto",
    "planner_learning_rate": None,
    "planner_nll_beta": 0.0,
    "noise_std": None,
}


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


def train(algo: str, coef: float, seed: int, steps: int, every: int, options: dict[str, Any]) -> str:
    """
    One training run, evaluated every ``every`` steps: its JSON line.

    :param options: UDPO's arguments over :data:`DEFAULTS` (``noise_std``: a Gaussian action noise, None: none);
        those that differ from them are written in the line (``coef`` and these are ignored for SAC)
    """
    th.set_num_threads(1)
    start = time.time()
    if algo == "udpo":
        kwargs = {**DEFAULTS, **options}
        std = kwargs.pop("noise_std")
        noise = NormalActionNoise(np.zeros(2), std * np.ones(2)) if std else None
        env = Monitor(WallMazeEnv())
        model = UDPO("MultiInputPolicy", env, **SMALL_HER_SETTINGS, **kwargs, planner_coef=coef, action_noise=noise, seed=seed)
    else:
        model = SAC("MultiInputPolicy", Monitor(WallMazeEnv()), **SMALL_HER_SETTINGS, seed=seed)
    callback = CrossWallEval(every)
    model.learn(steps, callback=callback)
    reached, end = wall_detour_end(model)
    row = {"algo": algo, "planner_coef": coef if algo == "udpo" else None, "seed": seed, "steps": steps}
    if algo == "udpo":
        row.update({key: value for key, value in options.items() if value != DEFAULTS[key]})
    row.update(detour_end=[bool(reached), end.tolist()], evals=callback.rows, wall_time_s=round(time.time() - start, 1))
    return json.dumps(row)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--algo", nargs="+", choices=["udpo", "sac"], default=["udpo"])
    parser.add_argument("--coefs", type=float, nargs="+", default=[0.0, 1e-3, 1e-2])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--every", type=int, default=2000)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--plan-target", choices=["buffer", "policy"], default="buffer", help="UDPO's plan_target")
    parser.add_argument("--entropy-term", choices=["inverse_dynamics", "linearised"], default="inverse_dynamics")
    parser.add_argument("--ent-coef", default="auto", help="UDPO's ent_coef ('auto' or a number)")
    parser.add_argument("--planner-lr", type=float, default=None, help="UDPO's planner_learning_rate (default: its lr)")
    parser.add_argument("--nll-beta", type=float, default=0.0, help="UDPO's planner_nll_beta (beta-NLL)")
    parser.add_argument("--noise-std", type=float, default=None, help="UDPO's Gaussian action noise (default: none)")
    parser.add_argument("--id-interval", type=int, default=DEFAULTS["inverse_dynamics_interval"], help="UDPO's Delta")
    parser.add_argument("--id-steps", type=int, default=DEFAULTS["inverse_dynamics_gradient_steps"], help="I's steps a refit")
    args = parser.parse_args()
    ent_coef = args.ent_coef if args.ent_coef.startswith("auto") else float(args.ent_coef)
    options = {"plan_target": args.plan_target, "ent_coef": ent_coef, "noise_std": args.noise_std}
    options.update(planner_learning_rate=args.planner_lr, entropy_term=args.entropy_term, planner_nll_beta=args.nll_beta)
    options.update(inverse_dynamics_interval=args.id_interval, inverse_dynamics_gradient_steps=args.id_steps)
    runs = [(algo, coef) for algo in args.algo for coef in (args.coefs if algo == "udpo" else [0.0])]
    # seed-major order: a run cut short leaves every method with about the same seeds; lines in order of finishing
    jobs = [(algo, coef, seed, args.steps, args.every, options) for seed, (algo, coef) in itertools.product(args.seeds, runs)]
    with multiprocessing.get_context("spawn").Pool(args.jobs) as pool:
        for line in pool.imap_unordered(_train, jobs):
            print(line, flush=True)


def _train(job: tuple[str, float, int, int, int, dict[str, Any]]) -> str:
    return train(*job)


if __name__ == "__main__":
    main()
