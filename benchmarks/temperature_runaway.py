"""
How a SAC-style temperature runs away, read from UDPO (or ``LeanSAC``) runs' ``progress.csv``: per logged row between
``--start`` and ``--stop``, every ``--every`` rows, the temperature ``train/ent_coef``, the policy's entropy estimate
(``train/entropy``, or, in logs older than that key, ``-mean log pi`` recovered from the temperature's loss
``-log(alpha) (mean log pi + target)``), its gap to the target entropy, UDPO's plan error ``rollout/plan_error`` and
the critic loss. From the repository root::

    python -m benchmarks.temperature_runaway \\
        zoo_runs/high-dim-action-push/seed_2_source_diverged/progress.csv \\
        zoo_runs/high-dim-action-push/seed_0_source_progress.csv --start 50000 --stop 75000 --every 6
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas

COLUMNS = ("train/ent_coef", "train/critic_loss", "rollout/plan_error")


def entropy(frame: pandas.DataFrame, target_entropy: float) -> pandas.Series:
    """
    The policy's entropy estimate per row: ``train/entropy`` where logged, else recovered from the temperature's loss
    (undefined where ``alpha`` is 1, ``log(alpha) = 0``).

    :param frame: a ``progress.csv``
    :param target_entropy: the run's target entropy
    """
    if "train/entropy" in frame:
        return frame["train/entropy"]
    log_alpha = np.log(frame["train/ent_coef"])
    return target_entropy + frame["train/ent_coef_loss"] / log_alpha.where(log_alpha.abs() > 1e-3)


def table(path: Path, target_entropy: float, start: int, stop: int, every: int) -> str:
    """
    :param path: a ``progress.csv``
    :param target_entropy: the run's target entropy
    :param start: the first env step shown
    :param stop: the last env step shown
    :param every: one row in ``every``
    :return: a Markdown table
    """
    frame = pandas.read_csv(path).dropna(subset=["train/ent_coef"])
    frame = frame[(frame["time/total_timesteps"] >= start) & (frame["time/total_timesteps"] <= stop)].iloc[::every]
    estimate = entropy(frame, target_entropy)
    lines = [
        f"{path}",
        "| env steps | temperature | entropy | entropy - target | plan error | critic loss |",
        "|---:|---:|---:|---:|---:|---:|",
    ]
    for (_, row), value in zip(frame.iterrows(), estimate, strict=True):
        values = [row.get(column, np.nan) for column in COLUMNS]
        lines.append(
            f"| {row['time/total_timesteps']:.0f} | {values[0]:.3g} | {value:.2f} | {value - target_entropy:+.2f} "
            f"| {values[2]:.3g} | {values[1]:.3g} |"
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("progress", type=Path, nargs="+", help="progress.csv files")
    parser.add_argument("--target-entropy", type=float, default=0.0, help="the runs' target entropy (FETCH_PUSH_FAST: 0)")
    parser.add_argument("--start", type=int, default=0)
    parser.add_argument("--stop", type=int, default=10**9)
    parser.add_argument("--every", type=int, default=1)
    args = parser.parse_args()
    if args.every < 1:
        parser.error(f"--every must be at least 1, not {args.every}")
    print("$ python -m benchmarks.temperature_runaway " + " ".join(sys.argv[1:]))
    for path in args.progress:
        print(table(path, args.target_entropy, args.start, args.stop, args.every), end="\n\n")


if __name__ == "__main__":
    main()
