"""I fitted to noisy actions clipped to the bounds: error and std, with ACTION_FIT_BOUND (no argument) or the former
clamp (argument old). Usage: STEPS=1000 OMP_NUM_THREADS=1 python zoo_runs/sources/lambda/entropy_probes/fit_bound.py [old]"""

import sys

import torch as th

from sb3_pilot.common.distributions import squashed_gaussian_log_prob
from sb3_pilot.udpo.policies import InverseDynamics

old = len(sys.argv) > 1
if old:

    def lp(self, state, next_state, actions):
        mean, log_std = self.distribution_params(state, next_state)
        eps = th.finfo(actions.dtype).eps
        return squashed_gaussian_log_prob(th.atanh(actions.clamp(-1 + eps, 1 - eps)), mean, log_std)

    InverseDynamics.log_prob = lp
for seed in range(3):
    th.manual_seed(seed)
    n = 4096
    state = th.rand(n, 2) * 2 - 1
    actions = (th.rand(n, 2) * 2 - 1 + 0.3 * th.randn(n, 2)).clamp(-1, 1)  # noisy actions, clipped to the bounds
    next_state = state + 0.2 * actions
    model = InverseDynamics(2, 2, [64, 64])
    opt = th.optim.Adam(model.parameters(), lr=1e-3)
    for _step in range(int(__import__("os").environ.get("STEPS", 500))):
        idx = th.randint(0, n, (256,))
        loss = -model.log_prob(state[idx], next_state[idx], actions[idx]).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    with th.no_grad():
        pred, _ = model(state, next_state, deterministic=True)
    inner = (actions.abs() < 0.9).all(dim=1)
    print(
        f"{'old' if old else 'new'} seed {seed}: clipped share {(actions.abs() == 1).float().mean():.2f}, "
        f"error inner {(pred - actions)[inner].abs().mean():.4f}, all {(pred - actions).abs().mean():.4f}"
    )
    with th.no_grad():
        mean, _ = model.distribution_params(state, next_state)
    clipped = actions.abs() == 1
    print(
        "   pre-squash mean at clipped actions: median",
        mean[clipped].abs().median().item(),
        "max",
        mean[clipped].abs().max().item(),
    )
    with th.no_grad():
        mean, log_std = model.distribution_params(state, next_state)
    print(
        "   std at clipped: median",
        log_std[clipped].exp().median().item(),
        " std inner:",
        log_std[~clipped].exp().median().item(),
    )
