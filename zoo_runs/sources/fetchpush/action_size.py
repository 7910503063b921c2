"""
How large and where the deterministic actions of FetchPush checkpoints are, on one fixed set of states: every 20th
state of steps 20k-60k in a replay buffer (``--states``, raw observations, normalised by each checkpoint's own
``VecNormalize`` statistics). Per checkpoint: the mean ``|a|`` and mean ``a`` on x, y, z of the deterministic action.
For UDPO also where its action noise comes from: the mean per-state std of ``I``'s mean action over 8 plans whose noise
is drawn on the gripper's position only (``s'[:3]``) or on every other planner dimension (``s'[3:]``).

A checkpoint is ``FOLDER:STEP`` (``rl_model_<STEP>_steps.zip``, saved by ``--save-freq``) or ``FOLDER`` (the run's
final model); SAC + HER's folders hold ``lean_sac`` in their path.

    B=/tmp/early/sac/lean_sac/Pilot-FetchPush-v0_1 U=udpo/udpo/Pilot-FetchPush-v0_1
    python zoo_runs/sources/fetchpush/action_size.py --states $B $B /tmp/fp3/sac/lean_sac/Pilot-FetchPush-v0_1:100000 \
        /tmp/early/$U /tmp/fpL/$U:25000 /tmp/fpL/$U:50000 /tmp/fp8b5/$U:25000 /tmp/fp4B/$U:25000 /tmp/fp3u/$U:25000 \
        /tmp/fp7L0/$U:25000 /tmp/fp7L0/$U:50000 /tmp/fp7L0/$U:150000
"""

import argparse
from pathlib import Path

import numpy as np
import torch as th
from diagnose import load  # this folder's: a checkpoint and its VecNormalize statistics
from stable_baselines3.common.save_util import load_from_pkl

from sb3_pilot.sac import LeanSAC
from sb3_pilot.udpo import UDPO

PLANS = 8


def plan_noise_spread(model: UDPO, obs: dict[str, th.Tensor], dims: slice) -> np.ndarray:
    """Per-axis std (x, y, z) over ``PLANS`` plans of ``I``'s mean action, plan noise drawn on ``dims`` only."""
    distribution = model.policy.state_planner.distribution(obs)
    std = distribution.delta_log_std.exp()
    actions = []
    for _ in range(PLANS):
        plan = distribution.mean.clone()
        plan[:, dims] += th.randn_like(plan[:, dims]) * std[:, dims]
        actions.append(model.policy.inverse_dynamics(distribution.state, plan, deterministic=True)[0])
    return th.stack(actions)[..., :3].std(dim=0).mean(dim=0).numpy()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--states", required=True, help="zoo run folder holding replay_buffer.pkl (one env)")
    parser.add_argument("checkpoints", nargs="+", help="FOLDER:STEP or FOLDER")
    args = parser.parse_args()
    th.manual_seed(0)
    buffer = load_from_pkl(Path(args.states) / "replay_buffer.pkl")
    rows = np.arange(20_000, 60_000, 20)
    raw = {key: value[rows, 0] for key, value in buffer.observations.items()}
    print(f"# {len(rows)} states: every 20th of steps 20k-60k of {args.states}")
    for spec in args.checkpoints:
        model, normalize = load(spec, LeanSAC if "lean_sac" in spec else UDPO)
        obs = {key: th.as_tensor(value, dtype=th.float32) for key, value in normalize.normalize_obs(raw).items()}
        with th.no_grad():
            actions = model.policy._predict(obs, deterministic=True)[:, :3]
            line = (
                f"{spec}: deterministic |a| xyz {actions.abs().mean(dim=0).numpy().round(2)}, "
                f"a xyz {actions.mean(dim=0).numpy().round(2)}"
            )
            if isinstance(model, UDPO):
                gripper, others = plan_noise_spread(model, obs, slice(0, 3)), plan_noise_spread(model, obs, slice(3, None))
                line += (
                    f"; action std from plan noise on the gripper's position {gripper.round(2)}, "
                    f"on the other dimensions {others.round(2)}"
                )
        print(line, flush=True)


if __name__ == "__main__":
    main()
