"""Prototype: UDPO's entropy terms use log pi(a|s,g) of the policy with I linearised around the sampled plan:
u - mu_I = J sigma_h eps1 + sigma_I eps2 ~ N(0, J diag(sigma_h^2) J^T + diag(sigma_I^2)), J = d mu_I / d s' (detached)."""

import math

import torch as th
from torch.func import jacrev, vmap

from sb3_pilot.common.distributions import tanh_log_det
from sb3_pilot.udpo import policies


def plan_and_act(self, obs, deterministic=False):
    d = self.state_planner.distribution(obs)
    sp = d.sample(deterministic)
    s = d.state
    mean_I, log_std_I = self.inverse_dynamics.distribution_params(s, sp)
    if deterministic:
        return policies.Plan(d, sp, th.tanh(mean_I), th.zeros(mean_I.shape[0], device=mean_I.device))
    eps2 = th.randn_like(mean_I)
    u = mean_I + eps2 * log_std_I.exp()
    std_h = d.delta_log_std.exp()
    eps1 = ((sp - d.mean) / std_h).detach()

    def f(s1, sp1):
        return self.inverse_dynamics.distribution_params(s1[None], sp1[None])[0][0]

    J = vmap(jacrev(f, argnums=1))(s.detach(), sp.detach()).detach()  # (B, A, D)
    L = (J * std_h[:, None, :]).double()
    A = mean_I.shape[1]
    std_I = log_std_I.double().exp()
    v = (L @ eps1.double()[:, :, None])[:, :, 0] + std_I * eps2.double()
    cov = L @ L.transpose(1, 2) + th.diag_embed(std_I**2) + 1e-10 * th.eye(A, dtype=th.float64)
    chol = th.linalg.cholesky(cov)
    z = th.linalg.solve_triangular(chol, v[:, :, None], upper=False)[:, :, 0]
    log_prob = (-0.5 * (z**2).sum(1) - th.log(th.diagonal(chol, dim1=1, dim2=2)).sum(1)).float() - 0.5 * A * math.log(
        2 * math.pi
    )
    return policies.Plan(d, sp, th.tanh(u), log_prob - tanh_log_det(u))


policies.UDPOPolicy.plan_and_act = plan_and_act
