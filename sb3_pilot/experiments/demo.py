"""
The smallest genuine PILoT pipeline (``make demo``): the High-Dim-Action challenge (Fetch-Reach) at the named
``demo`` budget, one seed.

1. a source UDPO on Pilot/FetchReach-v0 (4-dim actions), through the RL Zoo, 8000 steps;
2. its state planner transferred, frozen, into a UDPO on Pilot/FetchReachHighDim-v0 (8-dim actions through
   ``h(a)``, 80% gravity), which then learns only its inverse dynamics and critics; the source's VecNormalize
   statistics go with it (frozen), so the planner sees states scaled as it was trained; 4000 steps;
3. SAC + HER trained from scratch on the same target, same steps;
4. the comparison table (``run_challenge`` prints it), and ``success.png`` / ``plan_error.png`` under
   ``<root>/high-dim-action/``.

All three use RL-Zoo's FetchReach settings, VecNormalize included (``RL_ZOO_FETCH_NORMALIZED``); every stage is
seeded, so the same seed gives the same numbers (one torch thread, CPU).

    python -m sb3_pilot.experiments.demo [--root zoo_runs/demo] [--seed 0] [--source-steps N] [--steps N]

Reruns resume: finished stages are skipped. ``--source-steps`` / ``--steps`` override the budget's step counts.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from sb3_pilot.experiments.challenges import CHALLENGES, run_challenge
from sb3_pilot.experiments.challenges.definitions import HER, PLANNER_TRANSFER
from sb3_pilot.experiments.plots import plot_challenge

CHALLENGE = "high-dim-action"
#: The named budget of ``make demo`` (``BUDGETS["demo"]``, ``CHALLENGES["high-dim-action"].steps["demo"]``).
BUDGET = "demo"


def main(argv: list[str] | None = None) -> None:
    """Run the demo and print what it measured."""
    parser = argparse.ArgumentParser(
        prog="python -m sb3_pilot.experiments.demo", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--root", default="zoo_runs/demo", help="output root (models under ROOT/high-dim-action/models)")
    parser.add_argument("--source-steps", type=int, default=None, help="env steps of the source UDPO (budget: 8000)")
    parser.add_argument("--steps", type=int, default=None, help="env steps of each target run (budget: 4000)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    start = time.perf_counter()
    steps = dict(CHALLENGES[CHALLENGE].steps[BUDGET])
    if args.source_steps is not None:
        steps["source"] = args.source_steps
    if args.steps is not None:
        steps["pilot"] = steps["her"] = args.steps
    summary = run_challenge(CHALLENGE, BUDGET, seeds=[args.seed], root=args.root, steps=steps, progress=sys.stdout.isatty())
    pngs = plot_challenge(Path(args.root) / CHALLENGE)
    pilot, her = (summary["methods"][name]["runs"][0] for name in (PLANNER_TRANSFER, HER))
    source = summary["stages"][f"seed_{args.seed}/source"]
    source_stage = next(stage for stage in CHALLENGES[CHALLENGE].stages if stage.name == "source")
    _, source_success = source_stage.curve(Path(args.root).resolve() / CHALLENGE / "models" / f"seed_{args.seed}" / "source")
    print(
        f"\nSource UDPO on Pilot/FetchReach-v0: {steps['source']} steps ({source['wall_time_s']:.0f} s), "
        f"final success {source_success[-1]:.2f}."
    )
    print(f"Target Pilot/FetchReachHighDim-v0, {steps['pilot']} steps each, success (10 episodes) per evaluation:")
    print(f"  env steps     {pilot['timesteps']}")
    print(f"  PILoT         {[round(rate, 2) for rate in pilot['success_rate']]}")
    print(f"  SAC+HER       {[round(rate, 2) for rate in her['success_rate']]}")
    area = {name: sum(run["success_rate"]) for name, run in (("PILoT", pilot), ("SAC+HER", her))}
    if area["PILoT"] > area["SAC+HER"]:
        reached = pilot["steps_to_90"]
        verdict = "UDPO with the transferred planner learned the target faster than SAC+HER" + (
            f" (90% success after {reached} steps; SAC+HER's final success {her['success_rate'][-1]:.2f})."
            if reached is not None
            else "."
        )
    elif area["PILoT"] < area["SAC+HER"]:
        verdict = "SAC+HER learned faster than PILoT here: at this budget the transfer did not pay off."
    elif area["PILoT"] == 0:
        verdict = "No difference at this budget: neither learned yet (try more --steps / --source-steps)."
    else:
        verdict = "No difference at this budget: both learned equally fast."
    if source_success[-1] < 0.9:
        verdict += " The source ended below 0.9 success: its planner is not a trained one yet."
    print(verdict + " One seed; zoo_runs/high-dim-action has 3 seeds at the cpu budget.")
    print(f"Plots: {', '.join(str(png) for png in pngs)}. Wall time {time.perf_counter() - start:.0f} s.")


if __name__ == "__main__":
    main()
