"""
cProfile of ``train()`` (400 gradient steps after 1500 env steps) of ``udpo_vs_sac``'s FetchReach task: where the
update's time goes, HER sampling included (``sample`` of SB3's ``HerReplayBuffer`` or of ``LeanHerReplayBuffer``).

    OMP_NUM_THREADS=1 python zoo_runs/udpo_vs_sac/profile_train.py udpo|lean_sac|sac
"""

import cProfile
import pstats
import sys
import time

import torch as th

from sb3_pilot.experiments.benchmarks.udpo_vs_sac import TASKS, make_model

th.set_num_threads(1)
algo = sys.argv[1]
udpo_kwargs = dict(inverse_dynamics_interval=200, inverse_dynamics_learning_rate=1e-3) if algo == "udpo" else {}
model = make_model(algo, TASKS["fetch-reach"], 0, udpo_kwargs)
model.learn(1500)
model.train(50, model.batch_size)
profiler = cProfile.Profile()
start = time.perf_counter()
profiler.enable()
model.train(400, model.batch_size)
profiler.disable()
print(f"{algo}: {(time.perf_counter() - start) / 400 * 1e3:.2f} ms per gradient step (under cProfile)")
pstats.Stats(profiler).sort_stats("cumtime").print_stats(25)
