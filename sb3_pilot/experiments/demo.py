"""
The smallest genuine PILoT pipeline (``make demo``): the High-Dim-Action challenge at a small budget, one seed.

1. a source UDPO on Pilot/FetchReach-v0 (4-dim actions), through the RL Zoo;
2. its state planner transferred, frozen, into a UDPO on Pilot/FetchReachHighDim-v0 (8-dim actions through
   ``h(a)``, 80% gravity), which then learns only its inverse dynamics and critics; the source's VecNormalize
   statistics go with it (frozen), so the planner sees states scaled as it was trained;
3. SAC + HER trained from scratch on the same target, same steps;
4. a comparison table and ``success.png`` / ``plan_error.png`` under ``<root>/high-dim-action/``.

All three use RL-Zoo's FetchReach settings, VecNormalize included (``RL_ZOO_FETCH_NORMALIZED``).

    python -m sb3_pilot.experiments.demo [--root zoo_runs/demo] [--steps 4000] [--source-steps 5000] [--seed 0]

Reruns resume: finished stages are skipped. The numbers are what one seed gives at this budget, not a verdict.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

from sb3_pilot.experiments.challenges import BUDGETS, CHALLENGES, run_challenge
from sb3_pilot.experiments.plots import plot_challenge

CHALLENGE = "high-dim-action"


def main(argv: list[str] | None = None) -> None:
    """Run the demo and print what it measured."""
    parser = argparse.ArgumentParser(
        prog="python -m sb3_pilot.experiments.demo", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--root", default="zoo_runs/demo", help="output root (models under ROOT/high-dim-action/models)")
    parser.add_argument("--source-steps", type=int, default=5000, help="env steps of the source UDPO")
    parser.add_argument("--steps", type=int, default=4000, help="env steps of each target run")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    start = time.perf_counter()
    budget = replace(BUDGETS["cpu"], name="demo", n_evals=5)
    summary = run_challenge(
        CHALLENGE,
        budget,
        seeds=[args.seed],
        root=args.root,
        steps={"source": args.source_steps, "pilot": args.steps, "her": args.steps},
        progress=sys.stdout.isatty(),
    )
    pngs = plot_challenge(Path(args.root) / CHALLENGE)
    pilot, her = (summary["methods"][name]["runs"][0] for name in ("UDPO+PILoT (planner transfer)", "SAC+HER (scratch)"))
    source = summary["stages"][f"seed_{args.seed}/source"]
    source_stage = next(stage for stage in CHALLENGES[CHALLENGE].stages if stage.name == "source")
    _, source_success = source_stage.curve(Path(args.root).resolve() / CHALLENGE / "models" / f"seed_{args.seed}" / "source")
    print(
        f"\nSource UDPO on Pilot/FetchReach-v0: {args.source_steps} steps ({source['wall_time_s']:.0f} s), "
        f"final success {source_success[-1]:.2f}."
    )
    print(f"Target Pilot/FetchReachHighDim-v0, {args.steps} steps each, success (10 episodes) per evaluation:")
    print(f"  env steps     {pilot['timesteps']}")
    print(f"  PILoT         {[round(rate, 2) for rate in pilot['success_rate']]}")
    print(f"  SAC+HER       {[round(rate, 2) for rate in her['success_rate']]}")
    area = {name: sum(run["success_rate"]) for name, run in (("PILoT", pilot), ("SAC+HER", her))}
    if area["PILoT"] > area["SAC+HER"]:
        verdict = "PILoT's transferred planner learned faster than SAC+HER here (one seed: an anecdote, not a result)."
    elif area["PILoT"] < area["SAC+HER"]:
        verdict = "SAC+HER learned faster than PILoT here: at this budget the transfer did not pay off."
    elif area["PILoT"] == 0:
        verdict = "No difference at this budget: neither learned yet (try more --steps / --source-steps)."
    else:
        verdict = "No difference at this budget: both learned equally fast (one seed)."
    print(verdict)
    print(f"Plots: {', '.join(str(png) for png in pngs)}. Wall time {time.perf_counter() - start:.0f} s.")


if __name__ == "__main__":
    main()
