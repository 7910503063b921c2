"""
The paper's claim about sources: UDPO learns the source tasks about as fast as HER. On each of the five source tasks,
UDPO + HER and SAC + HER train with the same budget and seeds, as two stages of the challenge runner (the zoo with this
package's YAML, resumable, ``summary.json`` and ``success.png`` per task), then a table with a verdict per task::

    python -m sb3_pilot.experiments.benchmarks.sources --budget cpu --seeds 0 --jobs 2 --root zoo_runs/sources

The Fetch tasks use RL-Zoo's FetchReach settings with VecNormalize for both methods (``RL_ZOO_FETCH_NORMALIZED``, as
the Fetch challenges), the others their ``hyperparams/<budget>`` entries.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from sb3_pilot.experiments.challenges import Challenge, ZooTrain, run_challenge
from sb3_pilot.experiments.challenges.definitions import RL_ZOO_FETCH_NORMALIZED

SOURCE_TASKS = ("Pilot/FetchReach-v0", "Pilot/FetchPush-v0", "Pilot/Reacher-v0", "Pilot/Maze2D-v0", "Pilot/PointLocomotion-v0")
UDPO_HER, SAC_HER = "UDPO+HER", "SAC+HER"
#: Smoke steps: past the first episodes of every env, so that HER samples (PointLocomotion: 4 envs x 500 steps).
SMOKE_STEPS = {"Pilot/FetchPush-v0": 500, "Pilot/PointLocomotion-v0": 2100}


def source_challenge(env_id: str) -> Challenge:
    """UDPO + HER beside SAC + HER on ``env_id``, two independent stages per seed."""
    name = "source-" + env_id.split("/")[-1].removesuffix("-v0").lower()
    smoke = SMOKE_STEPS.get(env_id, 300)
    return Challenge(
        name,
        f"UDPO + HER vs SAC + HER on the source task {env_id}, same budget",
        env_id,
        (
            ZooTrain("udpo", "udpo", env_id, "udpo.yml", method=UDPO_HER),
            ZooTrain("her", "sac", env_id, "sac.yml", method=SAC_HER),
        ),
        steps={"smoke": {"udpo": smoke, "her": smoke}},
        fast_hyperparams=RL_ZOO_FETCH_NORMALIZED if "Fetch" in env_id else {},
    )


def verdict(udpo: dict[str, Any], her: dict[str, Any]) -> str:
    """
    Whether UDPO learned as fast as HER, from the mean curves: compared at the highest of 90% / 50% success both
    reached (UDPO "as fast" within 1.25x HER's steps), else by which one reached 50% at all.

    :param udpo: ``summary["methods"][UDPO_HER]["mean"]``
    :param her: the same for SAC + HER
    """
    for level in (90, 50):
        udpo_steps, her_steps = udpo[f"steps_to_{level}"], her[f"steps_to_{level}"]
        if udpo_steps is not None and her_steps is not None:
            ratio = udpo_steps / her_steps
            pace = "as fast as HER" if ratio <= 1.25 else "slower than HER"
            return f"{pace} ({level}% at {ratio:.2f}x HER's steps)"
        if udpo_steps is not None or her_steps is not None:
            return f"{'UDPO' if udpo_steps is not None else 'HER'} only reached {level}%"
    return "neither reached 50% at this budget"


def table(summaries: list[dict[str, Any]]) -> str:
    """A markdown table: steps to 50% / 90% and final success (mean [min, max] over seeds) per task and method."""
    lines = [
        "| task (seeds) | method | env steps | steps to 50% | steps to 90% | final success | verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    for summary in summaries:
        methods = summary["methods"]
        for method in (UDPO_HER, SAC_HER):
            result = methods[method]
            finals = [run["success_rate"][-1] for run in result["runs"]]
            mean = result["mean"]
            first = method == UDPO_HER
            lines.append(
                f"| {summary['target_env'] + ' (' + str(len(summary['seeds'])) + ')' if first else ''} | {method} | "
                f"{mean['timesteps'][-1]} | {mean['steps_to_50'] or '-'} | {mean['steps_to_90'] or '-'} | "
                f"{sum(finals) / len(finals):.2f} [{min(finals):.2f}, {max(finals):.2f}] | "
                f"{verdict(methods[UDPO_HER]['mean'], methods[SAC_HER]['mean']) if first else ''} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m sb3_pilot.experiments.benchmarks.sources", description=__doc__)
    parser.add_argument("--budget", default="cpu")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--tasks", nargs="+", default=list(SOURCE_TASKS), choices=SOURCE_TASKS)
    parser.add_argument("--root", default="zoo_runs/sources")
    parser.add_argument("--jobs", type=int, default=1, help="stages at once (UDPO and HER of a seed run together)")
    parser.add_argument("--plot", action="store_true", help="write success.png per task")
    args = parser.parse_args(argv)
    summaries = []
    for env_id in args.tasks:
        challenge = source_challenge(env_id)
        summaries.append(run_challenge(challenge, args.budget, seeds=args.seeds, root=args.root, jobs=args.jobs))
        if args.plot:
            from sb3_pilot.experiments.plots import plot_challenge

            plot_challenge(Path(args.root) / challenge.name)
    text = table(summaries)
    (Path(args.root) / "table.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
