"""
``torch.compile`` on a SAC-like gradient step (64x64 actor and twin critics, batch 256, fused Adam, 1 thread), eager
and compiled alternately in blocks of 500 steps; prints the compile time and the ms per step of each block.

    OMP_NUM_THREADS=1 python zoo_runs/udpo_vs_sac/compile_probe.py
"""

import time

import torch as th
from torch import nn

th.set_num_threads(1)


def mlp(n_in: int, n_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(n_in, 64), nn.ReLU(), nn.Linear(64, 64), nn.ReLU(), nn.Linear(64, n_out))


class ActorLoss(nn.Module):
    """SAC's actor loss through a squashed Gaussian and the min of two critics."""

    def __init__(self) -> None:
        super().__init__()
        self.actor, self.q1, self.q2 = mlp(16, 8), mlp(20, 1), mlp(20, 1)

    def forward(self, obs: th.Tensor) -> th.Tensor:
        mean, log_std = self.actor(obs).chunk(2, -1)
        noise = th.randn_like(mean)
        action = th.tanh(mean + log_std.clamp(-20, 2).exp() * noise)
        log_prob = (-0.5 * noise**2 - log_std).sum(-1) - th.log(1 - action**2 + 1e-6).sum(-1)
        inputs = th.cat([obs, action], -1)
        return (0.1 * log_prob - th.min(self.q1(inputs), self.q2(inputs)).squeeze(-1)).mean()


model = ActorLoss()
optimizer = th.optim.Adam(model.parameters(), lr=1e-3, fused=True)
obs = th.randn(256, 16)


def step(loss_fn: nn.Module) -> None:
    optimizer.zero_grad()
    loss_fn(obs).backward()
    optimizer.step()


compiled = th.compile(model)
start = time.time()
step(compiled)
print(f"compile s {time.time() - start:.1f}")
for _ in range(3):
    for name, loss_fn in (("eager", model), ("compiled", compiled)):
        for _ in range(50):
            step(loss_fn)
        start = time.perf_counter()
        for _ in range(500):
            step(loss_fn)
        print(f"{name} {(time.perf_counter() - start) / 500 * 1e3:.2f} ms")
