"""
The walled maze's runs of ``wall_maze.py`` (JSON lines) as one table: per UDPO variant and SAC + HER, the IQM over
seeds and its stratified-bootstrap 95% interval (``sb3_pilot.experiments.statistics``) of the steps to 50% / 90% of
the sampled cross-wall success (20 episodes a checkpoint), of the area under that curve, and each variant's area
against SAC + HER's; how many seeds' deterministic test pair (``wall_detour_end``) went round the wall at 12k / 20k.

    python zoo_runs/sources/lambda/wall_maze_table.py zoo_runs/sources/lambda/wall_maze_16seeds.jsonl \
        --labelled "2-core" zoo_runs/sources/lambda/wall_maze_16seeds_local.jsonl

``--labelled LABEL FILE ...`` (repeatable): runs made elsewhere (another machine, other code), their methods named with
the label.
``--versus A B``: also method A against method B (names as in the table): area gain and steps-to-90% ratio.
"""

import argparse
import json
from collections import defaultdict
from pathlib import Path

from sb3_pilot.experiments.statistics import compare, format_estimate, method_statistics


def method_name(row: dict) -> str:
    """``SAC+HER`` or ``UDPO lambda <coef>``, with the options that differ from the wall test's teacher's."""
    if row.get("algo", "udpo") == "sac":  # lines written before --algo are UDPO's
        return "SAC+HER"
    keys = (
        "entropy_term",
        "plan_target",
        "ent_coef",
        "planner_learning_rate",
        "planner_nll_beta",
        "likelihood_goals",
        "noise_std",
        "inverse_dynamics_interval",
        "inverse_dynamics_gradient_steps",
        "detach_log_std",
    )
    options = "".join(f", {key} {row[key]}" for key in keys if row.get(key, False) is not False)
    return f"UDPO lambda {row['planner_coef']:g}{options}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", type=Path, nargs="+")
    parser.add_argument(
        "--labelled", nargs="+", action="append", default=[], metavar="LABEL FILE", help="a label, then its files"
    )
    parser.add_argument("--versus", nargs=2, action="append", default=[], metavar=("A", "B"), help="A against B")
    args = parser.parse_args()
    labelled = [("", path) for path in args.files]
    labelled += [(f" ({label})", Path(path)) for label, *paths in args.labelled for path in paths]
    runs: dict[str, list[dict]] = defaultdict(list)
    for label, path in labelled:
        for line in path.read_text().splitlines():
            row = json.loads(line)
            evals = row["evals"]
            runs[method_name(row) + label].append(
                {
                    "seed": row["seed"],
                    "timesteps": [e[0] for e in evals],
                    "success_rate": [e[2] / 20 for e in evals],
                    "pair": {e[0]: e[3] for e in evals},
                }
            )
    print(
        "| method | seeds | steps to 50%, IQM [95% CI] (reached) | steps to 90% | area | area - SAC+HER's "
        "| test pair round the wall at 12k / 20k |"
    )
    print("|---|---|---|---|---|---|---|")
    for method in sorted(runs, key=lambda name: (name != "SAC+HER", name)):
        stats = method_statistics(runs[method])
        steps = [
            f"{format_estimate(stats[key], 0)} ({stats[key]['reached']}/{stats['seeds']})"
            for key in ("steps_to_50", "steps_to_90")
        ]
        baseline = method == "SAC+HER" or "SAC+HER" not in runs
        gain = "" if baseline else format_estimate(compare(runs[method], runs["SAC+HER"])["area_gain"])
        pairs = " / ".join(str(sum(run["pair"][step] for run in runs[method])) for step in (12_000, 20_000))
        print(f"| {method} | {stats['seeds']} | {' | '.join(steps)} | {format_estimate(stats['area'])} | {gain} | {pairs} |")
    for first, second in args.versus:
        versus = compare(runs[first], runs[second])
        ratio = format_estimate(versus["steps_to_90_ratio"]) if versus["steps_to_90_ratio"] else "-"
        print(f"\n{first} against {second}: area {format_estimate(versus['area_gain'])}, steps to 90% {ratio}x")


if __name__ == "__main__":
    main()
