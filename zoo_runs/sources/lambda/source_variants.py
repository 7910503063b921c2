"""
Variants of UDPO on the sources, each one change to the runs of UDPO's default (lambda 1e-3, ``entropy_term``
"inverse_dynamics"), in ``npz/<task>_<variant>_seed_*.npz`` (README's commands), against UDPO's default and SAC + HER
on the same recipe: FetchReach against the sources benchmark's 10 seeds (``../source-fetchreach/summary.json``),
PointLocomotion, Reacher and Maze2D against ``curves.json``'s rows (lambda 1e-3, 3 seeds, and the sources table's
SAC + HER). IQM steps to 90% success, their ratios and the gain in the area under the success curve,
stratified-bootstrap 95% intervals (``sb3_pilot.experiments.statistics``).

    python zoo_runs/sources/lambda/source_variants.py > zoo_runs/sources/lambda/source_variants.txt
"""

import json
from pathlib import Path

import numpy as np

from sb3_pilot.experiments.statistics import compare, format_estimate, method_statistics

HERE = Path(__file__).parent
#: Per task: the npz prefix of its runs, and where UDPO's default and SAC + HER runs come from.
TASKS = {
    "Pilot/FetchReach-v0": ("fetchreach", "summary", ("UDPO+HER", "SAC+HER")),
    "Pilot/PointLocomotion-v0": ("pointlocomotion", "curves", ("UDPO lambda 0.001", "SAC+HER (sources table, first 80k)")),
    "Pilot/Reacher-v0": ("reacher", "curves", ("UDPO lambda 0.001", "SAC+HER (sources table)")),
    "Pilot/Maze2D-v0": ("maze2d", "curves", ("UDPO lambda 0.001", "SAC+HER (sources table)")),
}


def baselines(task: str) -> dict[str, list[dict]]:
    """
    UDPO's default and SAC + HER on ``task``, by ``"UDPO"`` / ``"SAC+HER"``, with their later seeds where there are
    some (``npz/<task>_udpo_seed_*.npz``, ``npz/<task>_sac_seed_*.npz``: the same commands at this package's code).
    """
    prefix, origin, (udpo, sac) = TASKS[task]
    if origin == "summary":
        methods = json.loads((HERE.parent / "source-fetchreach" / "summary.json").read_text())["methods"]
        runs = {"UDPO": methods[udpo]["runs"], "SAC+HER": methods[sac]["runs"]}
    else:
        methods = json.loads((HERE / "curves.json").read_text())[task]
        runs = {"UDPO": methods[udpo], "SAC+HER": methods[sac]}
    return {name: runs[name] + npz_runs(f"{prefix}_{infix}") for name, infix in (("UDPO", "udpo"), ("SAC+HER", "sac"))}


#: The variants, by their npz infix: what each changes from UDPO's default.
VARIANTS = {
    "linearised": 'entropy_term "linearised"',
    "idlr1e-3": "inverse_dynamics_learning_rate 1e-3",
    "plr1e-3": "planner_learning_rate 1e-3",
    "beta0.5": "planner_nll_beta 0.5",
    "lam1e-4": "planner_coef (lambda) 1e-4",
}


def npz_runs(name: str) -> list[dict]:
    """The runs ``npz/<name>_seed_*.npz``, one line of their success curve printed each."""
    runs = []
    for path in sorted(HERE.glob(f"npz/{name}_seed_*.npz")):
        data = np.load(path)
        curve = data["successes"].mean(axis=1)
        runs.append({"timesteps": data["timesteps"].tolist(), "success_rate": curve.tolist()})
        print(f"  {path.name}: {' '.join(f'{value:.1f}' for value in curve)}")
    return runs


def main() -> None:
    for task in TASKS:
        print(task)
        runs = baselines(task)
        for variant, change in VARIANTS.items():
            found = npz_runs(f"{TASKS[task][0]}_{variant}")
            if found:
                runs[change] = found
        for name, method_runs in runs.items():
            stats = method_statistics(method_runs)
            steps, seeds = stats["steps_to_90"], stats["seeds"]
            print(
                f"  {name}: {seeds} seeds, steps to 90% {format_estimate(steps, 0)} ({steps['reached']}/{seeds}), "
                f"final {format_estimate(stats['final_success'])}, area {format_estimate(stats['area'])}"
            )
        for change in [name for name in runs if name not in ("UDPO", "SAC+HER")]:
            for baseline in ("SAC+HER", "UDPO"):
                comparison = compare(runs[change], runs[baseline])
                ratio = comparison["steps_to_90_ratio"]
                ratio_text = f"{format_estimate(ratio)}x" if ratio is not None else "none reached 90%"
                print(
                    f"  {change} against {baseline}: steps to 90% {ratio_text}, "
                    f"area gain {format_estimate(comparison['area_gain'])}"
                )


if __name__ == "__main__":
    main()
