"""
The 40k-step Maze-Car runs of ``run.py`` (SAC+HER, the ``planned_progress`` bonus, exact landmarks) beside the
displacement-cosine runs of ``../maze-car-horizon`` (same setup, same seeds), read over all 40k steps and over their
first 20k, with ``rliable``'s statistics (:mod:`sb3_pilot.experiments.statistics`): each method against SAC+HER, and
the ``planned_progress`` bonus against the displacement cosine (the package's default similarity).

    python zoo_runs/maze-car-progress/analyze.py > zoo_runs/maze-car-progress/analysis.md
"""

from __future__ import annotations

import json
from pathlib import Path

from sb3_pilot.experiments.statistics import compare, first_steps, method_statistics, run_scores
from sb3_pilot.experiments.statistics import format_estimate as fmt

HERE = Path(__file__).parent
HER, DISPLACEMENT = "SAC+HER (scratch)", "HER+PILoT (bonus, displacement_cosine)"
PROGRESS, ORACLE = "HER+PILoT (bonus, planned_progress)", "HER+exact landmarks (bonus, planned_progress)"
#: (method, baseline) pairs compared, on the area under the success curve and the steps to 90%
COMPARISONS = ((DISPLACEMENT, HER), (PROGRESS, HER), (ORACLE, HER), (PROGRESS, DISPLACEMENT), (ORACLE, PROGRESS))


def load_methods() -> dict[str, list[dict]]:
    """The runs of every method; SAC+HER's of this folder are checked against the horizon folder's."""
    methods = {
        name: result["runs"]
        for name, result in json.loads((HERE / "maze-car-shipped/summary.json").read_text())["methods"].items()
    }
    horizon = json.loads((HERE.parent / "maze-car-horizon/maze-car-shipped/summary.json").read_text())["methods"]
    seeds = [run["seed"] for run in methods[HER]]
    earlier = {run["seed"]: run["success_rate"] for run in horizon[HER]["runs"]}
    same = sum(run["success_rate"] == earlier.get(run["seed"]) for run in methods[HER])
    print(f"SAC+HER here and in ../maze-car-horizon: identical curves on {same} of {len(seeds)} seeds\n")
    methods[DISPLACEMENT] = [run for run in horizon[DISPLACEMENT]["runs"] if run["seed"] in seeds]
    return methods


def main() -> None:
    methods = load_methods()
    print("| window | method | seeds | area | steps to 50% | steps to 90% (seeds reaching it) | final success |")
    print("|---|---|---|---|---|---|---|")
    windows = {last: {name: first_steps(runs, last) for name, runs in methods.items()} for last in (40_000, 20_000)}
    for last, window in windows.items():
        for name, runs in window.items():
            stats = method_statistics(runs)
            reached = sum(run_scores(r["timesteps"], r["success_rate"])["steps_to_90"] <= last for r in runs)
            print(
                f"| first {last // 1000}k | {name} | {len(runs)} | {fmt(stats['area'])} | {fmt(stats['steps_to_50'], 0)} | "
                f"{fmt(stats['steps_to_90'], 0)} ({reached}/{len(runs)}) | {fmt(stats['final_success'])} |"
            )
    print()
    print(
        "| window | method | against | area gain, IQM [95% CI] | P(improvement) | IQM steps to 90%, ratio [95% CI] | verdict |"
    )
    print("|---|---|---|---|---|---|---|")
    for last, window in windows.items():
        for method, baseline in (pair for pair in COMPARISONS if set(pair) <= set(window)):
            result = compare(window[method], window[baseline])
            ratio = fmt(result["steps_to_90_ratio"]) if result["steps_to_90_ratio"] else "-"
            print(
                f"| first {last // 1000}k | {method} | {baseline} | {fmt(result['area_gain'])} | "
                f"{fmt(result['probability_of_improvement'])} | {ratio} | {result['verdict']} |"
            )


if __name__ == "__main__":
    main()
