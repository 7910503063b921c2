"""
UDPO with ``entropy_term="linearised"`` on FetchReach (``npz/fetchreach_linearised_seed_*.npz``, the sources
benchmark's UDPO stage plus the option, README's command) against the sources benchmark's 10 seeds of UDPO (default
term) and SAC + HER (``../source-fetchreach/summary.json``): IQM steps to 90% success and their ratio, stratified
bootstrap 95% intervals (``sb3_pilot.experiments.statistics``).

    python zoo_runs/sources/lambda/fetchreach_entropy.py
"""

import json
from pathlib import Path

import numpy as np

from sb3_pilot.experiments.statistics import compare, format_estimate, method_statistics

HERE = Path(__file__).parent


def main() -> None:
    summary = json.loads((HERE.parent / "source-fetchreach" / "summary.json").read_text())
    runs = {name: summary["methods"][name]["runs"] for name in ("UDPO+HER", "SAC+HER")}
    runs["UDPO+HER linearised"] = []
    for path in sorted(HERE.glob("npz/fetchreach_linearised_seed_*.npz")):
        data = np.load(path)
        curve = data["successes"].mean(axis=1)
        runs["UDPO+HER linearised"].append({"timesteps": data["timesteps"].tolist(), "success_rate": curve.tolist()})
        print(path.name, " ".join(f"{value:.1f}" for value in curve))
    for name, method_runs in runs.items():
        stats = method_statistics(method_runs)
        steps, seeds = stats["steps_to_90"], stats["seeds"]
        print(f"{name}: {seeds} seeds, steps to 90% {format_estimate(steps, 0)} ({steps['reached']}/{seeds})")
    for baseline in ("SAC+HER", "UDPO+HER"):
        ratio = compare(runs["UDPO+HER linearised"], runs[baseline])["steps_to_90_ratio"]
        print(f"linearised against {baseline}: steps to 90% {format_estimate(ratio)}x")


if __name__ == "__main__":
    main()
