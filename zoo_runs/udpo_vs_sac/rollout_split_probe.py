"""
Where a training step's time goes, LeanSAC beside UDPO in one process: ``learn`` 2000 steps after 1500 on
``udpo_vs_sac``'s FetchReach task (64x64 networks, one thread, one gradient step per env step), split into ``train``
(the gradient steps, HER sampling included) and the rest (acting, env steps, storing):

    OMP_NUM_THREADS=1 python zoo_runs/udpo_vs_sac/rollout_split_probe.py
"""

import time
from collections.abc import Callable
from typing import Any

import torch as th

from sb3_pilot.experiments.benchmarks.udpo_vs_sac import TASKS, make_model

th.set_num_threads(1)
STEPS = 2000


class TimedTrain:
    """Wraps a model's ``train`` and adds up the seconds spent in it."""

    def __init__(self, train: Callable[..., None]):
        self.train, self.seconds = train, 0.0

    def __call__(self, *args: Any, **kwargs: Any) -> None:
        start = time.perf_counter()
        self.train(*args, **kwargs)
        self.seconds += time.perf_counter() - start


for algo in ("lean_sac", "udpo"):
    model = make_model(algo, TASKS["fetch-reach"], 0, {})
    model.learn(1500)
    model.train = timed = TimedTrain(model.train)
    start = time.perf_counter()
    model.learn(STEPS, reset_num_timesteps=False)
    total, train = (time.perf_counter() - start) / STEPS * 1e3, timed.seconds / STEPS * 1e3
    print(f"{algo}: per env step {total:.2f} ms, train {train:.2f} ms, rest {total - train:.2f} ms")
