"""
Floating-point work of one gradient step of SB3's SAC, LeanSAC and UDPO, counted by ``torch.utils.flop_counter`` on the
``udpo_vs_sac`` benchmark's settings (FetchReach-v4 64x64, Pilot/AntLocomotion-v0 256x256), over one inverse-dynamics
interval (so UDPO's refits of ``I`` are included at their rate), the ATen operators dispatched per gradient step (a
second pass over an interval, after the first), and the work of one acting forward pass per env step.

    OMP_NUM_THREADS=1 python zoo_runs/udpo_vs_sac/flop_probe.py
"""

import torch as th
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils.flop_counter import FlopCounterMode

from sb3_pilot.experiments.benchmarks.udpo_vs_sac import TASKS, make_model


class OpCounter(TorchDispatchMode):
    """Counts the ATen operators dispatched (at 64x64 a step's time is mostly their per-call overhead)."""

    def __init__(self) -> None:
        super().__init__()
        self.count = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.count += 1
        return func(*args, **(kwargs or {}))


th.set_num_threads(1)
for name, task in TASKS.items():
    interval = task.udpo_kwargs["inverse_dynamics_interval"]
    flops = {}
    for algo in ("sac", "lean_sac", "udpo"):
        model = make_model(algo, task, seed=0, udpo_kwargs={})
        model.learn(task.kwargs["learning_starts"] + 2 * 50 * task.n_envs)  # past warm-up, a few episodes stored
        model._n_updates = 0  # UDPO: the first of these steps refits I, as every interval-th does
        with FlopCounterMode(display=False) as counter:
            model.train(gradient_steps=interval, batch_size=task.kwargs["batch_size"])
        update = counter.get_total_flops() / interval
        with OpCounter() as ops:
            model.train(gradient_steps=interval, batch_size=task.kwargs["batch_size"])
        obs = model.env.reset()
        with FlopCounterMode(display=False) as counter:
            model.predict(obs, deterministic=False)
        act = counter.get_total_flops() / task.n_envs
        flops[algo] = (update, act, ops.count / interval)
    for algo, (update, act, n_ops) in flops.items():
        print(
            f"{name}: {algo}: {update / 1e6:.2f} MFLOP per gradient step ({update / flops['sac'][0]:.2f}x SB3 SAC's), "
            f"{n_ops:.0f} ATen ops ({n_ops / flops['sac'][2]:.2f}x), {act / 1e6:.3f} MFLOP acting per env step"
        )
