"""
``python -m sb3_pilot.experiments.challenges CHALLENGE --budget smoke|cpu|cpu-image|demo|paper --seeds N|A-B|A,B,...
[--root runs] [--plot] [--jobs N | --backend ray [--ray-address ADDR]] [--threads T] [--keep-going]
[--reuse-shipped | --variant NAME] [--stages NAME ...] [--no-progress] [--dry-run]``.

``--seeds 6`` runs seeds 0 .. 5; ``--seeds 3-5`` or ``--seeds 3,4,5`` those seeds alone (the others' records stay in
``summary.json``, and a later ``--seeds 6`` summarizes them all).

On a terminal it shows a live table of the running stages (env steps, elapsed, ETA); otherwise plain lines. Each
stage's output goes to ``stage.log`` in its folder, a zoo stage's command line to ``command.txt``.
"""

from __future__ import annotations

import argparse
import signal
import sys

from sb3_pilot.experiments.challenges.backends import BACKENDS, StageFailed
from sb3_pilot.experiments.challenges.definitions import (
    BUDGETS,
    CHALLENGES,
    REUSE_SHIPPED,
    VARIANTS,
    at_budget,
    challenge_variant,
    only_stages,
)
from sb3_pilot.experiments.challenges.runner import run_challenge
from sb3_pilot.experiments.challenges.stages import ShippedFileMissing


def parse_seeds(text: str) -> list[int]:
    """
    The seeds of ``--seeds``: a count ``N`` (seeds 0 .. N-1), or seeds named by ranges and commas (``3-5``, ``0,2``,
    ``0-2,5``).

    :param text: the argument
    :return: the seeds, in the order given
    :raise argparse.ArgumentTypeError: for anything else, a count below 1, a range going down or a repeated seed
    """
    if text.isdigit():
        if int(text) < 1:
            raise argparse.ArgumentTypeError(f"a count of seeds is at least 1 (--seeds 1 runs seed 0), got {text!r}")
        return list(range(int(text)))
    seeds: list[int] = []
    for part in text.split(","):
        first, dash, last = part.partition("-")
        if not first.isdigit() or (dash and not last.isdigit()):
            raise argparse.ArgumentTypeError(
                f"--seeds takes a count (6: seeds 0 .. 5) or seeds as ranges and commas (3-5, 0,2), got {text!r}"
            )
        low, high = int(first), int(last) if dash else int(first)
        if high < low:
            raise argparse.ArgumentTypeError(f"the seed range {part!r} goes down: write {high}-{low}")
        seeds.extend(range(low, high + 1))
    if len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"--seeds {text!r} names a seed twice")
    return seeds


def main(argv: list[str] | None = None) -> None:
    """Parse the command line and run the challenge(s)."""
    parser = argparse.ArgumentParser(
        prog="python -m sb3_pilot.experiments.challenges",
        description="Run (or resume) PILoT's transfer challenges through the RL Zoo.",
        epilog="\n".join(f"{name}: {challenge.description}" for name, challenge in CHALLENGES.items()),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("challenge", choices=[*CHALLENGES, "all"])
    parser.add_argument("--budget", choices=list(BUDGETS), default="smoke")
    parser.add_argument(
        "--seeds",
        type=parse_seeds,
        default=[0],
        help="the seeds: a count N runs seeds 0 .. N-1 (--seeds 1 is seed 0 alone); 3-5 or 3,4,5 runs those seeds "
        "(4-4: seed 4 alone)",
    )
    parser.add_argument("--root", default="runs", help="output root: writes ROOT/CHALLENGE/")
    parser.add_argument("--plot", action="store_true", help="render the PNGs afterwards (sb3_pilot.experiments.plots)")
    parser.add_argument(
        "--no-progress", action="store_true", help="plain lines even on a terminal (no live table of the running stages)"
    )
    parser.add_argument("-v", "--verbose", type=int, default=0, help="1: the zoo's and SB3's logs (in the stages' logs)")
    parser.add_argument(
        "--jobs", type=int, default=1, help="local backend: up to N stages at once on this machine (independent ones)"
    )
    parser.add_argument(
        "--backend", choices=BACKENDS, default="local", help="local: this machine (--jobs); ray: every stage a Ray task"
    )
    parser.add_argument(
        "--ray-address",
        default=None,
        help="ray backend: the cluster (ray.init's address, e.g. auto); none: a running Ray or a local one started here",
    )
    parser.add_argument(
        "--threads", type=int, default=1, help="torch threads per stage process (the CPUs each Ray task declares)"
    )
    parser.add_argument(
        "--keep-going",
        action="store_true",
        help="after a stage fails, go on with the stages that do not read from it (other seeds', baselines); without "
        "it no stage starts after a failure. Either way the running stages finish and are recorded",
    )
    parser.add_argument(
        "--dry-run",
        action="store_true",
        help="print the stages that would run (with their command lines) and those finished, and stop",
    )
    parser.add_argument(
        "--reuse-shipped",
        action="store_true",
        help=f"evaluate the models shipped in the repository instead of training them ({', '.join(REUSE_SHIPPED)}): "
        "writes ROOT/CHALLENGE-shipped/",
    )
    parser.add_argument(
        "--variant",
        default=None,
        help="run a named variant of the challenge instead (writes ROOT/CHALLENGE-VARIANT/): "
        + ", ".join(f"{name} --variant {variant}" for name, variants in VARIANTS.items() for variant in variants),
    )
    parser.add_argument(
        "--stages",
        nargs="+",
        default=None,
        help="run only these stages and those they read from (e.g. --stages her: the baseline alone, to size a budget "
        "before any PILoT run); the same stage folders as the whole challenge's, which a later full run reuses; "
        "summary.json keeps its records of the other stages",
    )
    args = parser.parse_args(argv)
    if args.backend == "ray" and args.jobs != 1:
        parser.error("--jobs is for the local backend: Ray runs as many stages at once as the cluster has CPUs")
    # SIGTERM ends the run as Ctrl-C does: the running stages are stopped (Ray tasks cancelled), none is left behind
    signal.signal(signal.SIGTERM, lambda signum, frame: sys.exit(128 + signum))
    names = list(CHALLENGES) if args.challenge == "all" else [args.challenge]
    if args.reuse_shipped and any(name not in REUSE_SHIPPED for name in names):
        parser.error(f"--reuse-shipped: shipped models exist for {', '.join(REUSE_SHIPPED)} only")
    if args.variant is not None:
        if args.reuse_shipped or args.challenge == "all":
            parser.error("--variant names one challenge's variant: not with 'all' nor --reuse-shipped")
        try:
            challenges = [challenge_variant(args.challenge, args.variant)]
        except ValueError as error:
            parser.error(str(error))
    else:
        challenges = [REUSE_SHIPPED[name] if args.reuse_shipped else CHALLENGES[name] for name in names]
    # a budget's own stages (cpu-image's), before --stages picks among them
    challenges = [at_budget(challenge, args.budget) for challenge in challenges]
    if args.stages is not None:
        try:
            challenges = [only_stages(challenge, args.stages) for challenge in challenges]
        except ValueError as error:
            parser.error(str(error))
    for challenge in challenges:
        try:
            run_challenge(
                challenge,
                args.budget,
                seeds=args.seeds,
                root=args.root,
                progress=False if args.no_progress else None,
                verbose=args.verbose,
                jobs=args.jobs,
                backend=args.backend,
                ray_address=args.ray_address,
                threads=args.threads,
                keep_going=args.keep_going,
                dry_run=args.dry_run,
            )
        except (StageFailed, ShippedFileMissing, ValueError) as error:  # ValueError: refused before any work
            sys.exit(f"{challenge.name}: {error}")
        if args.plot and not args.dry_run:
            from sb3_pilot.experiments.plots import plot_challenge

            plot_challenge(f"{args.root}/{challenge.name}")


if __name__ == "__main__":
    main()
