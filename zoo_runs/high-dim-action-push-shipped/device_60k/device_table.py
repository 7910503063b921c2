"""
The 14 device seeds of the High-Dim Push target (frozen shipped planner), stopped at about 61k steps, against the
challenge's SAC + HER seeds over the same first four evaluations (15k-60k): per-seed evaluations, and the area under
the success curve to 60k with the challenge's statistics (IQM, stratified-bootstrap 95% intervals).

    cd zoo_runs/high-dim-action-push-shipped/device_60k && python device_table.py > table.txt
"""

import json
from pathlib import Path

import numpy as np

from sb3_pilot.experiments.statistics import compare, format_estimate, method_statistics

HERE = Path(__file__).parent
HORIZON = 60_000
CENSORED_AT = 75_000  # the next evaluation on the challenge's 15k grid


def truncated(timesteps: list[int], success_rate: list[float]) -> dict[str, list]:
    keep = [i for i, step in enumerate(timesteps) if step <= HORIZON]
    return {"timesteps": [timesteps[i] for i in keep], "success_rate": [success_rate[i] for i in keep]}


def main() -> None:
    pilot = []
    print("| seed | evaluation success at 15k, 30k, 45k, 60k (10 episodes) |\n|---|---|")
    for path in sorted(HERE.glob("evaluations_pilot_seed_*.npz"), key=lambda p: int(p.stem.rsplit("_", 1)[1])):
        evaluations = np.load(path)
        run = truncated(evaluations["timesteps"].tolist(), evaluations["successes"].mean(axis=1).tolist())
        pilot.append(run)
        print(f"| {path.stem.rsplit('_', 1)[1]} | {' '.join(f'{rate:.1f}' for rate in run['success_rate'])} |")
    summary = json.loads((HERE.parent / "summary.json").read_text())
    her = [
        truncated(run["timesteps"], run["success_rate"])
        for method in summary["methods"].values()
        if method["stage"] == "her"
        for run in method["runs"]
    ]
    print("\n| method (seeds) | area to 60k, IQM [95% CI] | success at 60k, IQM [95% CI] | 90% by 60k |\n|---|---|---|---|")
    for name, runs in (("UDPO + PILoT, device", pilot), ("SAC + HER, challenge", her)):
        stats = method_statistics(runs, censored_at=CENSORED_AT)
        reached = stats["steps_to_90"]["reached"]
        print(
            f"| {name} ({len(runs)}) | {format_estimate(stats['area'])} | {format_estimate(stats['final_success'])} "
            f"| {reached}/{len(runs)} |"
        )
    gain = compare(pilot, her, censored_at=CENSORED_AT)
    print(f"\nArea gain to 60k: {gain['verdict']}")


if __name__ == "__main__":
    main()
