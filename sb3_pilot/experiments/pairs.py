"""
The results table of the transfer pairs: one row per challenge run (``<root>/<challenge>/summary.json``), per compared
method the steps to 50% and 90% success, the final success and the final distance to the goal (mean [min, max] over
seeds), and a verdict on the paper's claim ("HER+PILoT learns the target faster than HER").

    python -m sb3_pilot.experiments.pairs [ROOT=zoo_runs] [CHALLENGE ...] [--episodes 10]

Final distance: the mean ``||achieved_goal - desired_goal||`` at the end of the last evaluation's episodes, as
``summary.json`` records it (``final_distance``, from ``GoalEvalCallback``'s ``evaluations.npz`` or a guidance
stage's episodes); for summaries without it, the zoo's ``evaluations.npz``; runs made before that callback existed have their
final model (``models/``) played again for ``episodes`` deterministic episodes (``play_episodes``). Either goes to
``<root>/<challenge>/final_eval.json`` (reused if present, so the table can be rebuilt without the models).

Verdict, per PILoT method against SAC+HER (``level`` = HER's final mean success, at least 0.1; ``ratio`` = the first
evaluated step where PILoT's mean success reaches ``level``, over HER's last step):

- ``confirmed``: ``ratio <= 0.5`` (the issue's goal: HER's final success in at most half HER's steps);
- ``not at this budget``: neither method's mean success reached 0.5 (below that, success can be chance: on Push a
  goal drawn at the object's start counts without moving it), or PILoT reaches ``level`` but later than half HER's
  steps, or never but within 0.2 of HER's final success;
- ``refuted at this budget``: PILoT's final success is below HER's by more than 0.2.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from sb3_pilot.experiments.challenges.definitions import CHALLENGES, HER
from sb3_pilot.experiments.challenges.stages import load_zoo_model, play_episodes, zoo_run_dir
from sb3_pilot.experiments.evaluation import load_final_distances
from sb3_pilot.experiments.zoo import register

FINAL_EVAL = "final_eval.json"


def evaluate_final(run_dir: Path, episodes: int = 10) -> dict[str, Any]:
    """
    Final success and distance of each method's final model, per seed (see the module doc).

    :param run_dir: ``<root>/<challenge>``
    :param episodes: episodes per model
    :return: ``{method: {"seed_<k>": {"success": float, "distance": float}}}``, also written to ``final_eval.json``
    """
    register()  # the zoo's ALGOS gets "udpo"
    summary = json.loads((run_dir / "summary.json").read_text())
    challenge = CHALLENGES[summary["challenge"]]
    path = run_dir / FINAL_EVAL
    results: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}
    for stage in challenge.stages:
        if stage.method is None or not hasattr(stage, "algo"):  # zero-shot guidance: no trained target model
            continue
        for seed in summary["seeds"]:
            key = f"seed_{seed}"
            if key in results.get(stage.method, {}):
                continue
            model_path = stage.output(run_dir / "models" / key / stage.name)
            if not model_path.exists():
                continue
            evaluations = zoo_run_dir(run_dir / "models" / key / stage.name, stage.algo, stage.env_id) / "evaluations.npz"
            distances = load_final_distances(evaluations) if evaluations.exists() else None
            if distances is not None:  # recorded by GoalEvalCallback at every evaluation: its last one
                with np.load(evaluations) as data:
                    successes = list(data["successes"][-1])
                distances, episodes_used = [float(distances[-1])], len(successes)
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


def verdict(pilot: dict[str, Any], her: dict[str, Any]) -> str:
    """The verdict of one PILoT method against SAC+HER, from their ``summary.json`` entries (see the module doc)."""
    pilot_final = float(np.mean([run["success_rate"][-1] for run in pilot["runs"]]))
    her_final = float(np.mean([run["success_rate"][-1] for run in her["runs"]]))
    if pilot["mean"]["steps_to_50"] is None and her["mean"]["steps_to_50"] is None:
        # on Push, a goal drawn at the object's start is a success without moving: 0.1-0.4 is no learning
        return "not at this budget (neither reached 50% success)"
    level = max(her_final, 0.1)
    her_steps = her["mean"]["timesteps"][-1]
    reached = next(
        (step for step, rate in zip(pilot["mean"]["timesteps"], pilot["mean"]["success_rate"], strict=True) if rate >= level),
        None,
    )
    if reached is not None:
        ratio = reached / her_steps
        reaches = f"{level:.2f} success (HER's final: {her_final:.2f}) at {ratio:.2f}x HER's steps"
        if ratio <= 0.5:
            return f"confirmed: {reaches}"
        return f"not at this budget: {reaches} (goal <= 0.5x)"
    if her_final - pilot_final > 0.2:
        return f"refuted at this budget: final success {pilot_final:.2f} vs HER's {her_final:.2f}"
    return f"not at this budget: final success {pilot_final:.2f} vs HER's {her_final:.2f}, never reaches it"


def _spread(values: list[float], digits: int = 2) -> str:
    return f"{np.mean(values):.{digits}f} [{min(values):.{digits}f}, {max(values):.{digits}f}]" if values else "-"


def table(run_dirs: list[Path], episodes: int = 10) -> str:
    """The markdown results table of the given challenge runs (one block of rows per pair)."""
    lines = [
        "| pair (budget, seeds) | method | env steps | steps to 50% | steps to 90% | final success | final distance "
        "| verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for run_dir in run_dirs:
        summary = json.loads((run_dir / "summary.json").read_text())
        final = evaluate_final(run_dir, episodes)
        pair = f"{summary['challenge']} ({summary['budget']}, {len(summary['seeds'])} seed{'s' * (len(summary['seeds']) > 1)})"
        her = summary["methods"].get(HER)
        for method, result in summary["methods"].items():
            mean = result["mean"]
            finals = [run["success_rate"][-1] for run in result["runs"]]
            if all("final_distance" in run for run in result["runs"]):  # recorded in the summary: its last evaluation
                distances = [run["final_distance"][-1] for run in result["runs"]]
            else:
                distances = [entry["distance"] for entry in final.get(method, {}).values()]
            judged = verdict(result, her) if her is not None and method != HER else ""
            lines.append(
                f"| {pair} | {method} | {mean['timesteps'][-1]} | {mean['steps_to_50'] or '-'} | "
                f"{mean['steps_to_90'] or '-'} | {_spread(finals)} | {_spread(distances, 3)} | {judged} |"
            )
            pair = ""
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Print the results table of the challenge runs under ROOT."""
    parser = argparse.ArgumentParser(prog="python -m sb3_pilot.experiments.pairs", description=__doc__)
    parser.add_argument("root", nargs="?", default="zoo_runs")
    parser.add_argument("challenges", nargs="*", help="challenge folders under ROOT (default: every one with a summary)")
    parser.add_argument("--episodes", type=int, default=10, help="episodes per final model for the final distance")
    args = parser.parse_args(argv)
    root = Path(args.root)
    names = args.challenges or [name for name in CHALLENGES if (root / name / "summary.json").exists()]
    print(table([root / name for name in names], args.episodes))


if __name__ == "__main__":
    main()
