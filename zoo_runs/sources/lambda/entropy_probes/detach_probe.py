"""Walled-maze probe (wall_maze.py's runs, 20k steps): UDPO's entropy term with ``log sigma_I(s, s')`` held fixed in
the planner's gradient (``DETACH=1``), so that the plan is not paid for going where ``I`` is unsure (the values, so the
temperature's loss and the critic's target, are unchanged); without ``DETACH`` the package as it is (the same-machine
baseline). ``ENTROPY_TERM=linearised``: the linearised term (default: UDPO's default term). One JSON line per run, as
wall_maze.py's.

    OMP_NUM_THREADS=1 DETACH=1 python zoo_runs/sources/lambda/entropy_probes/detach_probe.py 1e-4 0 1 2 > OUT.jsonl
"""

import json
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import wall_maze

from sb3_pilot.common import distributions
from sb3_pilot.udpo import policies


def detached_log_prob(noise, log_std):
    """The diagonal Gaussian's reparameterised log-density with no gradient through ``log_std``."""
    return distributions.reparameterised_log_prob(noise, log_std.detach())


LINEARISED_LOG_PROB = policies.UDPOPolicy.linearised_log_prob


def detached_linearised_log_prob(self, distribution, planned_next_state, noise, log_std):
    """The linearised term with no gradient through ``log sigma_I`` (the planner's spread is its lever)."""
    return LINEARISED_LOG_PROB(self, distribution, planned_next_state, noise, log_std.detach())


def detach_log_std() -> None:
    """Patch both entropy terms so that no gradient reaches the plan through ``log sigma_I``."""
    policies.reparameterised_log_prob = detached_log_prob
    policies.UDPOPolicy.linearised_log_prob = detached_linearised_log_prob


if __name__ == "__main__":
    if os.environ.get("DETACH"):
        detach_log_std()
    coef, seeds = float(sys.argv[1]), [int(seed) for seed in sys.argv[2:]]
    options = {key: wall_maze.DEFAULTS[key] for key in ("plan_target", "ent_coef", "noise_std")}
    options["entropy_term"] = os.environ.get("ENTROPY_TERM", wall_maze.DEFAULTS["entropy_term"])
    for seed in seeds:
        line = wall_maze.train("udpo", coef, seed, 20_000, 2000, options)
        print(json.dumps({**json.loads(line), "detach_log_std": bool(os.environ.get("DETACH"))}), flush=True)
