"""Seed-0 probe of the walled maze every 2k steps (policy spread, temperature, planned step, I's std, cross-wall
success). Usage (repository root): OMP_NUM_THREADS=1 python zoo_runs/sources/lambda/entropy_probes/diag.py udpo 1e-3 0 10000
['{"inverse_dynamics_gradient_steps": 200}'] (or: sac 0 0 12000); LINPI=1 loads linpi_patch.py,
DETACH=1 detach_probe.py's variant. Outputs: diag_*.txt."""

import json
import sys

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[4] / "tests"))
import os

import torch as th
from maze_envs import SMALL_HER_SETTINGS, UDPO_SETTINGS, WallMazeEnv
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor

if os.environ.get("LINPI"):
    import linpi_patch  # noqa
if os.environ.get("DETACH"):  # detach_probe.py's variant: no gradient to the plan through log sigma_I
    from detach_probe import detach_log_std

    detach_log_std()
from sb3_pilot import UDPO

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
from wall_maze_teacher import cross_wall_successes


class Diag(BaseCallback):
    def _on_step(self):
        if self.num_timesteps % 2000:
            return True
        m = self.model
        st = th.get_rng_state()
        with th.no_grad():
            data = m.replay_buffer.sample(512)
            obs = data.observations
            rep = {k: v.repeat(16, *[1] * (v.dim() - 1)) for k, v in obs.items()}
            if isinstance(m, UDPO):
                d = m.policy.state_planner.distribution(obs)
                step = d.delta_mean[:, :2].abs().mean().item()
                pstd = d.delta_log_std.exp().mean().item()
                _mean_I, logstd_I = m.policy.inverse_dynamics.distribution_params(d.state, d.mean)
                Istd = logstd_I.exp().mean().item()
                det = m.policy.plan_and_act(obs, deterministic=True).actions
                samp = m.policy.plan_and_act(rep).actions.view(16, 512, -1)
                lp = m.policy.plan_and_act(obs).log_prob.mean().item()
                extra = dict(plan_step=round(step, 3), planner_std=round(pstd, 4), I_std=round(Istd, 4), logp=round(lp, 2))
            else:
                det = m.actor(obs, deterministic=True)
                a, lpt = m.actor.action_log_prob(rep)
                samp = a.view(16, 512, -1)
                extra = dict(logp=round(lpt.mean().item(), 2))
            ent = m.log_ent_coef.exp().item() if m.log_ent_coef is not None else None
        th.set_rng_state(st)
        s = cross_wall_successes(m, WallMazeEnv(), deterministic=False, repeats=5)
        th.set_rng_state(st)
        print(
            json.dumps(
                dict(
                    name=NAME,
                    t=self.num_timesteps,
                    sat=round((det.abs() > 0.99).float().mean().item(), 3),
                    det_abs=round(det.abs().mean().item(), 3),
                    act_std=round(samp.std(0).mean().item(), 4),
                    alpha=round(ent, 4),
                    cross=s,
                    **extra,
                )
            ),
            flush=True,
        )
        return True


algo, coef, seed = sys.argv[1], float(sys.argv[2]), int(sys.argv[3])
EXTRA = json.loads(sys.argv[5]) if len(sys.argv) > 5 else {}
NAME = f"{algo}{coef if algo == 'udpo' else ''}-s{seed}{EXTRA}"
th.set_num_threads(1)
env = Monitor(WallMazeEnv())
if algo == "udpo":
    m = UDPO("MultiInputPolicy", env, **SMALL_HER_SETTINGS, **{**UDPO_SETTINGS, **EXTRA}, planner_coef=coef, seed=seed)
else:
    m = SAC("MultiInputPolicy", env, **SMALL_HER_SETTINGS, seed=seed)
m.learn(int(sys.argv[4]) if len(sys.argv) > 4 else 12000, callback=Diag())
