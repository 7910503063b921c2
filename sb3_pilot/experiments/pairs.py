"""
The results table of the transfer pairs: one row per challenge run (``<root>/<challenge>/summary.json``) and compared
method, with its seeds and the number of distinct sources they read from, the ``rliable`` statistics of
:mod:`sb3_pilot.experiments.statistics` (interquartile mean over seeds, "mean" where it cuts none, and
stratified-bootstrap 95% intervals of the area under the success curve, the steps to 50% and 90% success and the
final success; the probability of improvement over SAC+HER), the final distance to the goal (mean [min, max] over
seeds), the ratio of the IQM steps to 90% to SAC+HER's with its interval (a bound where one side's seeds did not all
reach 90%; ``-`` where none did or the method is zero-shot) and a verdict on the paper's claim ("HER+PILoT learns
the target faster than HER"). The statistics are also written into each ``summary.json`` (``statistics``).

    python -m sb3_pilot.experiments.pairs [ROOT=runs] [CHALLENGE ...] [--episodes 10] [--reps 2000]

Final distance: the mean ``||achieved_goal - desired_goal||`` at the end of the last evaluation's episodes, as
``summary.json`` records it (``final_distance``, from ``GoalEvalCallback``'s ``evaluations.npz`` or a guidance
stage's episodes); for summaries without it, the zoo's ``evaluations.npz``; runs made before that callback existed have their
final model (``models/``) played again for ``episodes`` deterministic episodes (``play_episodes``). Either goes to
``<root>/<challenge>/final_eval.json`` (reused if present, so the table can be rebuilt without the models).

Verdict, per PILoT method against SAC+HER (a guided controller: against the same controller unguided, where the
challenge runs it, and the verdict names it), on the gain ``IQM(area_PILoT) - IQM(area_HER)`` and its 95% interval
(:func:`~sb3_pilot.experiments.statistics.verdict`): ``confirmed`` when the interval lies above 0 on at least 5 seeds
per method from at least 5 distinct sources (where a method reads one), ``worse than SAC+HER`` when it lies below 0
on as many, ``a hint`` when only the estimate lies above 0 or the interval does on fewer seeds or sources, ``no gain
shown`` otherwise, and no verdict under 3 seeds per method.

Where the methods read a trained source (``source`` in ``summary.json``, or read from the models of a summary written
before the runner recorded it), the pair's label says how many seeds' sources learned their own task (final success
at least :data:`~sb3_pilot.experiments.challenges.runner.SOURCE_LEARNED`) and, where some did and some did not, the
rows of the methods that read it follow again over the seeds whose source learned, against SAC+HER's every seed (it
reads no source): a subset chosen after the fact, whose verdict is at most ``a hint``. The rows over all seeds stay
the headline.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_pilot.experiments.challenges.definitions import CHALLENGES, HER, REUSE_SHIPPED, VARIANTS, at_budget
from sb3_pilot.experiments.challenges.runner import count_sources, describe_source, mean_curve, source_learning
from sb3_pilot.experiments.challenges.stages import play_episodes, zoo_run_dir
from sb3_pilot.experiments.evaluation import load_final_distances
from sb3_pilot.experiments.statistics import REPS, aggregate_name, format_estimate, format_seeds, summary_statistics
from sb3_pilot.experiments.zoo import register
from sb3_pilot.experiments.zoo_run import load_zoo_model

FINAL_EVAL = "final_eval.json"
#: Every challenge by its output folder's name, those of ``--reuse-shipped`` and ``--variant`` included.
BY_FOLDER = {
    challenge.name: challenge
    for challenge in (
        *CHALLENGES.values(),
        *REUSE_SHIPPED.values(),
        *(variant for variants in VARIANTS.values() for variant in variants.values()),
    )
}


def evaluate_final(run_dir: Path, episodes: int = 10) -> dict[str, Any]:
    """
    Final success and distance of each method's final model, per seed (see the module doc).

    :param run_dir: ``<root>/<challenge>``
    :param episodes: episodes per model
    :return: ``{method: {"seed_<k>": {"success": float, "distance": float}}}``, also written to ``final_eval.json``
    """
    register()  # the zoo's ALGOS gets "udpo"
    summary = json.loads((run_dir / "summary.json").read_text())
    challenge = at_budget(BY_FOLDER[summary["challenge"]], summary["budget"])
    path = run_dir / FINAL_EVAL
    results: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}
    for stage in challenge.stages:
        if stage.method is None or not hasattr(stage, "algo"):  # zero-shot guidance: no trained target model
            continue
        for seed in summary["seeds"]:
            key = f"seed_{seed}"
            model_path = stage.output(run_dir / "models" / key / stage.name)
            if not model_path.exists():  # models not kept: what final_eval.json recorded, if anything
                continue
            evaluations = zoo_run_dir(run_dir / "models" / key / stage.name, stage.algo, stage.env_id) / "evaluations.npz"
            distances = load_final_distances(evaluations) if evaluations.exists() else None
            if distances is not None:  # recorded by GoalEvalCallback at every evaluation: its last one (a re-run's)
                with np.load(evaluations) as data:
                    successes = list(data["successes"][-1])
                distances, episodes_used = [float(distances[-1])], len(successes)
            elif key in results.get(stage.method, {}):  # replayed before
                continue
            else:  # a run from before GoalEvalCallback: play the final model again
                model, vec_normalize = load_zoo_model(model_path)
                env = gym.make(stage.env_id, **getattr(stage, "env_kwargs", {}))
                successes, distances = [], []
                for observation, info in play_episodes(model, vec_normalize, env, episodes, seed):
                    successes.append(float(info["is_success"]))
                    distances.append(float(np.linalg.norm(observation["achieved_goal"] - observation["desired_goal"])))
                env.close()
                episodes_used = episodes
            results.setdefault(stage.method, {})[key] = {
                "success": float(np.mean(successes)),
                "distance": float(np.mean(distances)),
                "episodes": episodes_used,
            }
            path.write_text(json.dumps(results, indent=1))
    return results


def _aggregate(seeds: int) -> str:
    """``mean `` where the IQM over ``seeds`` cuts none (it is the mean), else nothing (the column says IQM)."""
    return "mean " if aggregate_name(seeds) == "mean" else ""


def _steps(entry: dict[str, Any], seeds: int, zero_shot: bool) -> str:
    """IQM of the steps to a success rate and how many seeds reached it (the others counted at ``censored_at``)."""
    if entry["reached"] == 0:
        return f"never (0/{seeds})"
    if zero_shot:  # evaluated after 0 target steps only
        return f"at 0 steps ({entry['reached']}/{seeds})"
    low, high = entry["ci"]
    return f"{_aggregate(seeds)}{entry['value']:.0f} [{low:.0f}, {high:.0f}] ({entry['reached']}/{seeds})"


def _pace(ratio: dict[str, Any] | None, pilot: dict[str, Any], her: dict[str, Any]) -> str:
    """
    The ratio of the IQM steps to 90% and its interval, read as a bound where seeds of one side never reached 90% (they
    count at ``censored_at``, which understates that side's steps): at most when SAC+HER's were censored, at least
    when the PILoT method's were.
    """
    if ratio is None:
        return "-"
    censored = [stats["seeds"] - stats["steps_to_90"]["reached"] for stats in (pilot, her)]
    bound = {(False, True): "at most ", (True, False): "at least "}.get((censored[0] > 0, censored[1] > 0), "")
    text = f"{bound}{format_estimate(ratio)}"
    return text + " (censored seeds on both sides)" if all(censored) else text


def _spread(values: list[float], digits: int = 2) -> str:
    return f"{np.mean(values):.{digits}f} [{min(values):.{digits}f}, {max(values):.{digits}f}]" if values else "-"


def add_statistics(run_dir: Path, reps: int = REPS) -> dict[str, Any]:
    """
    Compute the ``rliable`` statistics of a challenge run (:func:`~sb3_pilot.experiments.statistics.summary_statistics`,
    SAC+HER the baseline) and write them into its ``summary.json`` under ``statistics``. A summary written before
    the runner recorded each method's distinct sources gets them from its stages' hashes
    (:func:`~sb3_pilot.experiments.challenges.runner.count_sources`; unknown for a stage its challenge no longer has),
    and one written before it recorded how the trained source learned gets that from the source's models where they
    are still there (:func:`~sb3_pilot.experiments.challenges.runner.source_learning`).

    :param run_dir: ``<root>/<challenge>``
    :param reps: bootstrap replications
    :return: the summary with its statistics
    """
    path = run_dir / "summary.json"
    summary = json.loads(path.read_text())
    challenge = BY_FOLDER.get(summary["challenge"])
    challenge = None if challenge is None else at_budget(challenge, summary["budget"])
    for result in summary["methods"].values():
        if result.get("sources") is None and challenge is not None:
            seeds = [run["seed"] for run in result["runs"]]
            result["sources"] = count_sources(challenge, result["stage"], summary["stages"], seeds)
    if "source" not in summary and challenge is not None:
        source = source_learning(challenge, summary["seeds"], run_dir, summary["stages"])
        summary.update({} if source is None else {"source": source})
    summary["statistics"] = summary_statistics(summary, HER, reps=reps)
    path.write_text(json.dumps(summary, indent=1))
    return summary


def _row(
    pair: str,
    method: str,
    runs: list[dict[str, Any]],
    statistics: dict[str, Any],
    her: dict[str, Any] | None,
    final: dict[str, Any],
) -> str:
    """
    One row of the results table: a method over ``runs``.

    :param pair: the pair's cell (empty but in a pair's first row)
    :param method: the method
    :param runs: its runs (all its seeds, or a subset)
    :param statistics: the statistics of those runs (``{"methods", "comparisons"}``)
    :param her: SAC+HER's statistics (None where the challenge has no SAC+HER)
    :param final: ``final_eval.json``'s (:func:`evaluate_final`)
    """
    stats = statistics["methods"][method]
    if all("final_distance" in run for run in runs):  # recorded in the summary: its last evaluation
        distances = [run["final_distance"][-1] for run in runs]
    else:
        seeds = {f"seed_{run['seed']}" for run in runs}
        distances = [entry["distance"] for key, entry in final.get(method, {}).items() if key in seeds]
    comparison = statistics["comparisons"].get(method)
    timesteps = mean_curve(runs)["timesteps"]
    zero_shot = timesteps == [0]
    improvement = format_estimate(comparison["probability_of_improvement"]) if comparison else ""
    pace = ""
    if comparison and her is not None:
        pace = _pace(None if zero_shot else comparison["steps_to_90_ratio"], stats, her)
    mean = _aggregate(stats["seeds"])
    return (
        f"| {pair} | {method} | {format_seeds(stats['seeds'], stats['sources'])} | "
        f"{timesteps[-1]} | {mean}{format_estimate(stats['area'])} | "
        f"{_steps(stats['steps_to_50'], stats['seeds'], zero_shot)} | "
        f"{_steps(stats['steps_to_90'], stats['seeds'], zero_shot)} | "
        f"{mean}{format_estimate(stats['final_success'])} | {_spread(distances, 3)} | {improvement} | {pace} | "
        f"{comparison['verdict'] if comparison else ''} |"
    )


def table(run_dirs: list[Path], episodes: int = 10, reps: int = REPS) -> str:
    """
    The markdown results table of the given challenge runs (one block of rows per pair, and the rows over the seeds
    whose source learned where only some did: see the module doc); their statistics are written into their
    ``summary.json`` (:func:`add_statistics`).
    """
    lines = [
        "| pair (budget, seeds) | method | seeds (sources) | env steps | area under the success curve, IQM [95% CI] "
        "| steps to 50%, IQM [95% CI] (seeds reaching it) | steps to 90% | final success, IQM [95% CI] "
        "| final distance, mean [min, max] | P(improvement over SAC+HER, or the baseline the verdict names) [95% CI] "
        "| steps to 90%, IQM ratio to SAC+HER's [95% CI] | verdict |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for run_dir in run_dirs:
        summary = add_statistics(run_dir, reps)
        final = evaluate_final(run_dir, episodes)
        seeds = len(summary["seeds"])
        source = summary.get("source")
        learned = f"; {describe_source(source)}" if source else ""
        pair = f"{summary['challenge']} ({summary['budget']}, {seeds} seed{'s' * (seeds > 1)}{learned})"
        statistics = summary["statistics"]
        her = statistics["methods"].get(HER)
        for method, result in summary["methods"].items():
            lines.append(_row(pair, method, result["runs"], statistics, her, final))
            pair = ""
        split = statistics.get("source_learned", {})
        pair = (
            f"{summary['challenge']}, only the {len(split.get('seeds', ()))} seeds whose source learned (a subset chosen "
            f"after the fact: at most a hint; SAC+HER over all its seeds, it reads no source)"
        )
        for method in split.get("methods", {}):
            runs = [run for run in summary["methods"][method]["runs"] if run["seed"] in split["seeds"]]
            lines.append(_row(pair, method, runs, split, her, final))
            pair = ""
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Print the results table of the challenge runs under ROOT."""
    parser = argparse.ArgumentParser(prog="python -m sb3_pilot.experiments.pairs", description=__doc__)
    parser.add_argument("root", nargs="?", default="runs", help="the challenges' output root (committed results: zoo_runs)")
    parser.add_argument("challenges", nargs="*", help="challenge folders under ROOT (default: every one with a summary)")
    parser.add_argument("--episodes", type=int, default=10, help="episodes per final model for the final distance")
    parser.add_argument("--reps", type=int, default=REPS, help="bootstrap replications of the intervals")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.reps < 1:
        parser.error(f"--episodes and --reps must be at least 1, got {args.episodes} and {args.reps}")
    root = Path(args.root)
    names = args.challenges or [name for name in BY_FOLDER if (root / name / "summary.json").exists()]
    missing = [name for name in names if not (root / name / "summary.json").exists()]
    if not names or missing:
        where = ", ".join(str(root / name) for name in missing) or f"any challenge folder of {root}"
        parser.error(f"no summary.json in {where} (a challenge writes one: python -m sb3_pilot.experiments.challenges)")
    print(table([root / name for name in names], args.episodes, args.reps))


if __name__ == "__main__":
    main()
