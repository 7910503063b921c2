"""
UDPO + HER (lambda 1e-4, linearised entropy term) against SAC + HER on Fetch-Push, both with the 50k-step random
warm-up (``FETCH_PUSH_FAST``), over every seed whose files are in ``--folder``: the ``rliable`` IQM over seeds of the
steps to 50% / 90% success, its stratified-bootstrap 95% interval, and the ratio of the two methods' IQM steps to 90%
with its interval (the sources' rule: at most 1.1x), computed by ``sb3_pilot.experiments.statistics`` and
``benchmarks.sources.verdict``. Every run is judged on the 150k budget: a seed that never reached a threshold by then
counts one interval past it, also when it stopped before 150k (crashed, or stopped by hand: each curve says where it
ends).

Two measures of the same runs:

- ``evaluation``: the zoo's deterministic evaluations (20 episodes) on the 25k grid up to 150k steps, which every
  seed has (``evaluations_<run>_seed_<s>.npz``; seeds 2+ were evaluated every 12.5k, read on the 25k grid here and on
  their own grid in the last table). A seed that stopped before 150k has a shorter curve.
- ``training``: the success of the sampled policy's training episodes per 10k steps from 50k (``monitor_<run>_seed_<s>.csv``,
  the zoo's ``0.monitor.csv``; about 200 episodes per point).

From the repository root::

    python -m benchmarks.fetchpush_seeds                  # zoo_runs/sources/fetchpush/seeds.txt
    python -m benchmarks.fetchpush_seeds --udpo udpo_linearised_lambda1e-4_alpha0.1_warmup50k --out seeds_alpha0.1.txt

``--udpo RUN --out FILE`` reports another UDPO variant's seeds against the same SAC + HER seeds (above: an initial
temperature of 0.1); ``--seeds 0 1 2 3`` keeps those seeds of both methods.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas

from benchmarks.sources import verdict
from sb3_pilot.experiments.statistics import compare, format_estimate, method_statistics

FOLDER = Path("zoo_runs/sources/fetchpush")
RUNS = {"UDPO+HER": "udpo_linearised_lambda1e-4_warmup50k", "SAC+HER": "sac_target_entropy0_warmup50k"}
LAST, GRID, WINDOW, START = 150_000, 25_000, 10_000, 50_000


def evaluation_runs(folder: Path, run: str, grid: int | None) -> list[dict]:
    """Each seed's deterministic evaluations in ``folder`` up to :data:`LAST` steps, on multiples of ``grid`` (None: all)."""
    runs = []
    for path in sorted(folder.glob(f"evaluations_{run}_seed_*.npz")):
        data = np.load(path)
        keep = (data["timesteps"] <= LAST) & ((data["timesteps"] % grid == 0) if grid else True)
        if grid is None and np.all(data["timesteps"] % GRID == 0):
            continue  # a seed evaluated on the 25k grid only
        runs.append(
            {
                "seed": int(path.stem.rsplit("_", 1)[1]),
                "timesteps": data["timesteps"][keep].tolist(),
                "success_rate": data["successes"][keep].mean(axis=1).tolist(),
            }
        )
    return runs


def training_runs(folder: Path, run: str) -> list[dict]:
    """Each seed's training-episode success in ``folder`` per :data:`WINDOW` steps from :data:`START` to :data:`LAST`."""
    runs = []
    for path in sorted(folder.glob(f"monitor_{run}_seed_*.csv")):
        episodes = pandas.read_csv(path, skiprows=1)  # SB3's Monitor file: a JSON header line, then the episodes
        ends = episodes["l"].cumsum().to_numpy()
        success = episodes["is_success"].to_numpy(dtype=float)
        windows = [end for end in range(START + WINDOW, LAST + 1, WINDOW) if end <= ends[-1]]
        rates = [success[(ends > end - WINDOW) & (ends <= end)].mean() for end in windows]
        runs.append({"seed": int(path.stem.rsplit("_", 1)[1]), "timesteps": windows, "success_rate": rates})
    return runs


def report(title: str, udpo: list[dict], her: list[dict], interval: int) -> str:
    """
    A markdown table of both methods' statistics and the verdict with the ratio's interval, every run judged on the
    budget: a threshold not reached by :data:`LAST` counts at ``LAST + interval``, whether the run went on to the budget
    or stopped before it (crashed, or stopped by hand: ``last`` says where).
    """
    censored_at = LAST + interval
    lines = [
        f"### {title}",
        "",
        "| method | seeds | steps to 50% | steps to 90% | final | curves |",
        "|---|---|---|---|---|---|",
    ]
    stats = {}
    for method, runs in (("UDPO+HER", udpo), ("SAC+HER", her)):
        stats[method] = method_statistics(runs, censored_at=censored_at)
        curves = "; ".join(
            f"{run['seed']}: " + " ".join(f"{rate:.2f}" for rate in run["success_rate"]) + f" (last {run['timesteps'][-1]})"
            for run in runs
        )
        steps = [
            f"{format_estimate(stats[method][key], 0)} ({stats[method][key]['reached']}/{len(runs)})"
            for key in ("steps_to_50", "steps_to_90")
        ]
        final = format_estimate(stats[method]["final_success"])
        lines.append(f"| {method} | {len(runs)} | {steps[0]} | {steps[1]} | {final} | {curves} |")
    ratio = compare(udpo, her, censored_at=censored_at)["steps_to_90_ratio"]
    lines += ["", f"Verdict (UDPO+HER against SAC+HER): {verdict(stats['UDPO+HER'], stats['SAC+HER'], ratio)}", ""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--folder", type=Path, default=FOLDER, help="the runs' evaluations and monitor files")
    parser.add_argument("--udpo", default=RUNS["UDPO+HER"], help="the UDPO run's file-name stem")
    parser.add_argument("--out", default="seeds.txt", help="output file, in --folder")
    parser.add_argument("--seeds", type=int, nargs="+", help="only these seeds of both methods (default: every seed here)")
    args = parser.parse_args()
    folder, udpo, her = args.folder, args.udpo, RUNS["SAC+HER"]
    if not any(folder.glob(f"evaluations_{udpo}_seed_*.npz")):
        parser.error(f"no evaluations_{udpo}_seed_*.npz in {folder} (run from the repository root, or pass --folder)")
    measures = {
        "Deterministic evaluations, 25k grid to 150k": (
            evaluation_runs(folder, udpo, GRID),
            evaluation_runs(folder, her, GRID),
            GRID,
        ),
        "Training episodes, success per 10k steps from 60k to 150k": (
            training_runs(folder, udpo),
            training_runs(folder, her),
            WINDOW,
        ),
        "Deterministic evaluations, 12.5k grid (the seeds evaluated on it)": (
            evaluation_runs(folder, udpo, None),
            evaluation_runs(folder, her, None),
            GRID // 2,
        ),
    }
    if args.seeds is not None:  # e.g. the tables of an earlier sitting, before more seeds came
        measures = {
            title: (
                [run for run in udpo_runs if run["seed"] in args.seeds],
                [run for run in her_runs if run["seed"] in args.seeds],
                interval,
            )
            for title, (udpo_runs, her_runs, interval) in measures.items()
        }
    text = "\n".join(report(title, *runs) for title, runs in measures.items() if runs[0] and runs[1])
    print(text)
    (folder / args.out).write_text(text + "\n")


if __name__ == "__main__":
    main()
