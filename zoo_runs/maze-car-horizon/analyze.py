"""
The 40k-step Maze-Car runs (``run.py``) read two ways: over all 40k steps and over their first 20k (the committed
budget's window), each with ``rliable``'s statistics (:mod:`sb3_pilot.experiments.statistics`) and the ratio of the
IQM steps to 90% (HER+PILoT over SAC+HER) with its stratified-bootstrap 95% interval.

    python zoo_runs/maze-car-horizon/analyze.py > zoo_runs/maze-car-horizon/analysis.md
"""

from __future__ import annotations

import json
from pathlib import Path

from sb3_pilot.experiments.statistics import compare, first_steps, method_statistics, run_scores
from sb3_pilot.experiments.statistics import format_estimate as fmt

SUMMARY = Path(__file__).parent / "maze-car-shipped" / "summary.json"
PILOT, HER = "HER+PILoT (bonus, displacement_cosine)", "SAC+HER (scratch)"


def main() -> None:
    methods = json.loads(SUMMARY.read_text())["methods"]
    print("| window | method | area | steps to 50% | steps to 90% (seeds) | final success |")
    print("|---|---|---|---|---|---|")
    comparisons = []
    for last in (40_000, 20_000):
        pilot, her = (first_steps(methods[name]["runs"], last) for name in (PILOT, HER))
        for name, runs in ((PILOT, pilot), (HER, her)):
            stats = method_statistics(runs)
            reached = sum(run_scores(r["timesteps"], r["success_rate"])["steps_to_90"] <= last for r in runs)
            print(
                f"| first {last // 1000}k | {name} | {fmt(stats['area'])} | {fmt(stats['steps_to_50'], 0)} | "
                f"{fmt(stats['steps_to_90'], 0)} ({reached}/{len(runs)}) | {fmt(stats['final_success'])} |"
            )
        comparisons.append((last, compare(pilot, her)))
    print()
    print("| window | area gain, IQM [95% CI] | P(improvement) | IQM steps to 90%, PILoT / HER [95% CI] | verdict |")
    print("|---|---|---|---|---|")
    for last, result in comparisons:
        print(
            f"| first {last // 1000}k | {fmt(result['area_gain'])} | {fmt(result['probability_of_improvement'])} | "
            f"{fmt(result['steps_to_90_ratio'])} | {result['verdict']} |"
        )


if __name__ == "__main__":
    main()
