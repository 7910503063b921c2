"""
The smallest genuine PILoT pipeline (``make demo``), two of its transfers on a CPU in about four minutes.

Planner transfer: the High-Dim-Action challenge (Fetch-Reach) at the named ``demo`` budget, one seed.

1. a source UDPO on Pilot/FetchReach-v0 (4-dim actions), through the RL Zoo, 8000 steps;
2. its state planner transferred, frozen, into a UDPO on Pilot/FetchReachHighDim-v0 (8-dim actions through
   ``h(a)``, 80% gravity), which then learns only its inverse dynamics; the source's VecNormalize
   statistics go with it (frozen), so the planner sees states scaled as it was trained; 4000 steps;
3. SAC + HER trained from scratch on the same target, same steps;
4. the comparison table (``run_challenge`` prints it), and ``success.png`` / ``plan_error.png`` under
   ``<root>/high-dim-action/``.

All three use RL-Zoo's FetchReach settings, VecNormalize included (``RL_ZOO_FETCH_NORMALIZED``); every stage is
seeded, so the same seed gives the same numbers on the same machine (one torch thread, CPU; another CPU's
floating point follows other trajectories).

Reward bonus: the Maze-Car pair with the shipped Maze2D goal planner (``maze-car --reuse-shipped``), HER + PILoT
(displacement-cosine bonus) and SAC + HER on the car side by side, ``--bonus-seeds`` seeds (1) at its ``cpu`` budget
(20k steps; each further seed adds about two minutes on two cores). A few seeds of a sparse-reward task cannot tell a
gain from noise: the demo prints their areas under the success curve beside the run of the same stages committed in
``zoo_runs/maze-car-shipped``.

    python -m sb3_pilot.experiments.demo [--root runs/demo] [--seed 0] [--source-steps N] [--steps N]
        [--bonus-seeds N] [--bonus-steps N]

On a terminal each run shows a live table of its running stages (env steps, elapsed, ETA); each stage's output and
command line go to its folder. Reruns resume: finished stages are skipped. ``--source-steps`` / ``--steps`` override
the High-Dim-Action budget's step counts, ``--bonus-steps`` the Maze-Car ones; ``--bonus-seeds 0`` skips the bonus.
Installed from a wheel, without the repository's ``zoo_runs/``, the demo runs the planner transfer and skips the
bonus, saying why.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from sb3_pilot.experiments.challenges import CHALLENGES, REUSE_SHIPPED, only_stages, run_challenge
from sb3_pilot.experiments.challenges.definitions import HER, PILOT_DISPLACEMENT, PLANNER_TRANSFER
from sb3_pilot.experiments.challenges.stages import REPO_DIR, ShippedFileMissing
from sb3_pilot.experiments.plots import plot_challenge
from sb3_pilot.experiments.statistics import run_scores

CHALLENGE = "high-dim-action"
#: The named budget of ``make demo`` (``BUDGETS["demo"]``, ``CHALLENGES["high-dim-action"].steps["demo"]``).
BUDGET = "demo"
#: The bonus part: Maze-Car with the shipped planner, its displacement-cosine bonus and SAC+HER, at this budget.
BONUS_CHALLENGE = only_stages(REUSE_SHIPPED["maze-car"], ["pilot_disp", "her"])
BONUS_BUDGET = "cpu"
#: The committed run of the same stages, the reference the demo's few seeds are printed beside.
BONUS_REFERENCE = REPO_DIR / "zoo_runs" / "maze-car-shipped" / "summary.json"
#: The committed High-Dim-Action run at the cpu budget, whose seeds the demo's one seed is printed beside.
PLANNER_REFERENCE = REPO_DIR / "zoo_runs" / CHALLENGE / "summary.json"


def planner_transfer(root: str, seed: int, source_steps: int | None, target_steps: int | None) -> list[Path]:
    """
    High-Dim-Action at the ``demo`` budget, one seed: run it, print what it measured.

    :return: the plots written
    """
    steps = dict(CHALLENGES[CHALLENGE].steps[BUDGET])
    if source_steps is not None:
        steps["source"] = source_steps
    if target_steps is not None:
        steps["pilot"] = steps["her"] = target_steps
    summary = run_challenge(CHALLENGE, BUDGET, seeds=[seed], root=root, steps=steps, jobs=2)
    pngs = plot_challenge(Path(root) / CHALLENGE)
    pilot, her = (summary["methods"][name]["runs"][0] for name in (PLANNER_TRANSFER, HER))
    source = summary["stages"][f"seed_{seed}/source"]
    source_stage = next(stage for stage in CHALLENGES[CHALLENGE].stages if stage.name == "source")
    _, source_success = source_stage.curve(Path(root).resolve() / CHALLENGE / "models" / f"seed_{seed}" / "source")
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
    if PLANNER_REFERENCE.exists():
        reference = json.loads(PLANNER_REFERENCE.read_text())
        where = PLANNER_REFERENCE.parent.relative_to(REPO_DIR)
        verdict += f" One seed; {where} has {len(reference['seeds'])} seeds at the {reference['budget']} budget."
    print(verdict)
    return pngs


def _areas(summary: dict[str, Any], method: str) -> list[float]:
    """The area under the success curve of each seed of ``method`` (:func:`~sb3_pilot.experiments.statistics.run_scores`)."""
    return [run_scores(run["timesteps"], run["success_rate"])["area"] for run in summary["methods"][method]["runs"]]


def reward_bonus(root: str, seeds: int, steps: int | None) -> list[Path]:
    """
    Maze-Car, HER + PILoT's bonus against SAC + HER, ``seeds`` seeds: run it, print the areas beside the reference.

    :return: the plots written
    """
    stage_steps = None if steps is None else {"pilot_disp": steps, "her": steps}
    summary = run_challenge(BONUS_CHALLENGE, BONUS_BUDGET, seeds=range(seeds), root=root, steps=stage_steps, jobs=2)
    pngs = plot_challenge(Path(root) / BONUS_CHALLENGE.name)
    print(
        f"\nReward bonus on Pilot/Maze2DCar-v0 (shipped Maze2D planner), {seeds} seed(s) of "
        f"{summary['methods'][HER]['mean']['timesteps'][-1]} steps, area under the success curve per seed:"
    )
    for method in (PILOT_DISPLACEMENT, HER):
        print(f"  {method:40s} {[round(area, 2) for area in _areas(summary, method)]}")
    if BONUS_REFERENCE.exists():
        reference = json.loads(BONUS_REFERENCE.read_text())
        gain = reference["statistics"]["comparisons"][PILOT_DISPLACEMENT]
        print(
            f"{seeds} seed(s) cannot tell a gain from noise (seeds 0-2 of the committed run did not either). The committed "
            f"{len(reference['seeds'])}-seed run of the same stages ({BONUS_REFERENCE.relative_to(REPO_DIR)}): "
            f"{gain['verdict']}, IQM areas {reference['statistics']['methods'][PILOT_DISPLACEMENT]['area']['value']:.2f} "
            f"(bonus) vs {reference['statistics']['methods'][HER]['area']['value']:.2f} (SAC+HER)."
        )
    return pngs


def main(argv: list[str] | None = None) -> None:
    """Run the demo and print what it measured."""
    parser = argparse.ArgumentParser(
        prog="python -m sb3_pilot.experiments.demo", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--root", default="runs/demo", help="output root (models under ROOT/<challenge>/models)")
    parser.add_argument("--source-steps", type=int, default=None, help="env steps of the source UDPO (budget: 8000)")
    parser.add_argument("--steps", type=int, default=None, help="env steps of each High-Dim-Action target run (budget: 4000)")
    parser.add_argument("--seed", type=int, default=0, help="High-Dim-Action's seed")
    parser.add_argument("--bonus-seeds", type=int, default=1, help="Maze-Car seeds 0 .. N-1 (0: no bonus part)")
    parser.add_argument("--bonus-steps", type=int, default=None, help="env steps of each Maze-Car run (budget: 20000)")
    args = parser.parse_args(argv)
    if args.bonus_seeds < 0:
        parser.error(f"--bonus-seeds must be >= 0, got {args.bonus_seeds}")

    start = time.perf_counter()
    pngs = planner_transfer(args.root, args.seed, args.source_steps, args.steps)
    if args.bonus_seeds:
        try:
            pngs += reward_bonus(args.root, args.bonus_seeds, args.bonus_steps)
        except ShippedFileMissing as error:  # installed from a wheel: the shipped planner is in the repository only
            print(f"\nReward bonus skipped: {error}")
    print(f"Plots: {', '.join(str(png) for png in pngs)}. Wall time {time.perf_counter() - start:.0f} s.")


if __name__ == "__main__":
    main()
