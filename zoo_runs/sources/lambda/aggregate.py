"""
Aggregates the lambda (``planner_coef``) runs per task with ``sb3_pilot.experiments.statistics`` (IQM over seeds of
steps to 90%, final success and the area under the success curve, stratified-bootstrap 95% intervals): copies each
run's curve into ``curves.json`` (the source of the table, with where it came from) and prints ``table.md``.

    python zoo_runs/sources/lambda/aggregate.py [--scratch /tmp/lambda] [--add /tmp/probe] > zoo_runs/sources/lambda/table.md

With ``--scratch`` it first collects the runs' evaluations from the scratch folder into ``curves.json``; with ``--add``
it adds the Reacher and Maze2D runs of a later scratch folder (:func:`collect_more`) to those already there; with
``--add-high-dim ROOT COEF`` the High-Dim-Action runs of ``high_dim.py --coefs COEF --root ROOT``; without any, it only
re-renders the table from ``curves.json``.
"""

import argparse
import csv
import json
from pathlib import Path

import numpy as np

from sb3_pilot.experiments.statistics import method_statistics

HERE = Path(__file__).resolve().parent
SOURCES = HERE.parent
COEFS = ("0", "0.001", "0.005", "0.01")


def npz_curve(path: Path, last: int | None = None) -> dict:
    data = np.load(path)
    steps, success = data["timesteps"].tolist(), data["successes"].mean(axis=1).round(3).tolist()
    if last is not None:
        keep = [i for i, step in enumerate(steps) if step <= last]
        steps, success = [steps[i] for i in keep], [success[i] for i in keep]
    return {"timesteps": steps, "success_rate": success}


def summary_runs(path: Path, method: str, last: int | None = None) -> list[dict]:
    runs = []
    for run in json.loads(path.read_text())["methods"][method]["runs"]:
        keep = [i for i, step in enumerate(run["timesteps"]) if last is None or step <= last]
        runs.append(
            {
                "seed": run["seed"],
                "timesteps": [run["timesteps"][i] for i in keep],
                "success_rate": [run["success_rate"][i] for i in keep],
            }
        )
    return runs


def last_plan_error(path: Path) -> float | None:
    """The last ``rollout/plan_error`` (the planner's mean against the real next state, MSE per dimension) of a zoo
    log (``| plan_error | 0.8 |`` rows) or of a challenge stage's ``progress.csv``."""
    if not path.exists():
        return None
    if path.suffix == ".csv":
        rows = list(csv.DictReader(path.open()))
        values = [row["rollout/plan_error"] for row in rows if row.get("rollout/plan_error")]
    else:
        values = [line.split("|")[2] for line in path.read_text().splitlines() if "plan_error" in line]
    return round(float(values[-1]), 3) if values else None


def scratch_runs(scratch: Path, folder: str, env_id: str, coefs: tuple[str, ...]) -> dict[str, list[dict]]:
    """The zoo runs ``scratch/<folder>/lam_<coef>_seed_<k>`` (seeds 0-2) and their logs, by ``UDPO lambda <coef>``."""
    methods = {}
    for coef in coefs:
        runs = []
        for seed in range(3):
            path = scratch / f"{folder}/lam_{coef}_seed_{seed}/udpo/{env_id.replace('/', '-')}_1/evaluations.npz"
            if path.exists():
                plan_error = last_plan_error(scratch / f"{folder}_lam_{coef}_seed_{seed}.log")
                runs.append({"seed": seed, **npz_curve(path), "final_plan_error": plan_error})
        if runs:
            methods[f"UDPO lambda {float(coef):g}"] = runs
    return methods


def collect(scratch: Path) -> dict:
    tasks: dict = {}
    # a. FetchReach, 10k steps
    fetch = tasks.setdefault("Pilot/FetchReach-v0", {})
    fetch.update(scratch_runs(scratch, "fetchreach", "Pilot/FetchReach-v0", ("0.0", "0.001", "0.01")))
    fetch["SAC+HER (sources table)"] = summary_runs(SOURCES / "old-lambda/source-fetchreach/summary.json", "SAC+HER")
    # b. wall maze: cross-wall successes of 4 pairs, deterministic once + sampled 5 times (24 episodes)
    wall = tasks.setdefault("wall maze (tests/maze_envs.py)", {})
    jsonl = scratch / "wall_maze.jsonl"
    if jsonl.exists():
        for line in jsonl.read_text().splitlines():
            row = json.loads(line)
            runs = wall.setdefault(f"UDPO lambda {row['planner_coef']:g}", [])
            runs.append(
                {
                    "seed": row["seed"],
                    "timesteps": [e[0] for e in row["evals"]],
                    "success_rate": [round((e[1] + e[2]) / 24, 3) for e in row["evals"]],
                    "deterministic_of_4": [e[1] for e in row["evals"]],
                    "sampled_of_20": [e[2] for e in row["evals"]],
                    "test_pair_reached": [e[3] for e in row["evals"]],
                    "detour_end_20k": row["detour_end"],
                    "wall_time_s": row["wall_time_s"],
                }
            )
    # c. PointLocomotion, 80k steps
    point = tasks.setdefault("Pilot/PointLocomotion-v0", {})
    point["UDPO lambda 0"] = [
        {
            "seed": s,
            **npz_curve(SOURCES / f"ablation/evaluations_lambda0_seed_{s}.npz"),
            "final_plan_error": last_plan_error(SOURCES / f"ablation/lambda0_seed_{s}.log"),
            "from": "../ablation",
        }
        for s in range(3)
    ]
    point.update(scratch_runs(scratch, "pl", "Pilot/PointLocomotion-v0", ("0.001", "0.01")))
    summary = SOURCES / "source-pointlocomotion/summary.json"
    point["UDPO lambda 0.005 (preset, sources table, first 80k)"] = summary_runs(summary, "UDPO+HER", 80_000)
    point["SAC+HER (sources table, first 80k)"] = summary_runs(summary, "SAC+HER", 80_000)
    # d. High-Dim-Action: the source (FetchReach, 8k) and the transfer (FetchReachHighDim, 8k)
    for coef in ("0", "0.001", "0.01"):
        add_high_dim(tasks, scratch / "high_dim", coef)
    # lambda 1e-2 (the preset then) and SAC + HER: the challenge's own cpu run, earlier code
    transfer = tasks.setdefault("high-dim-action: transfer", {})
    shipped = SOURCES.parent / "high-dim-action/summary.json"
    transfer["UDPO lambda 0.01 (zoo_runs/high-dim-action)"] = summary_runs(shipped, "UDPO+PILoT (planner transfer)")
    transfer["SAC+HER (zoo_runs/high-dim-action)"] = summary_runs(shipped, "SAC+HER (scratch)")
    return tasks


#: The High-Dim-Action rows: the source (FetchReach, 8k steps) and the transfer (FetchReachHighDim, 8k), by stage.
HIGH_DIM_TASKS = {"high-dim-action: source Pilot/FetchReach-v0": "source", "high-dim-action: transfer": "pilot"}


def add_high_dim(tasks: dict, root: Path, coef: str) -> None:
    """The runs of ``high_dim.py --coefs COEF --root ROOT`` (seeds 0-2), as rows "UDPO lambda COEF (source's)"."""
    challenge = root / f"lambda_{coef}/high-dim-action"
    for task, stage in HIGH_DIM_TASKS.items():
        runs = []
        for seed in range(3):
            found = sorted((challenge / f"models/seed_{seed}/{stage}").glob("**/evaluations.npz"))
            if found:
                plan_error = last_plan_error(challenge / f"models/seed_{seed}/{stage}/progress.csv")
                runs.append({"seed": seed, **npz_curve(found[0]), "final_plan_error": plan_error})
        if runs:
            tasks.setdefault(task, {})[f"UDPO lambda {float(coef):g} (source's)"] = runs


def scratch_seeds(folder: Path, env_id: str) -> list[dict]:
    """The zoo runs ``folder/seed_<k>`` (seeds 0-2) and their logs ``<folder>_seed_<k>.log``."""
    runs = []
    for seed in range(3):
        path = folder / f"seed_{seed}/udpo/{env_id.replace('/', '-')}_1/evaluations.npz"
        if path.exists():
            plan_error = last_plan_error(folder.parent / f"{folder.name}_seed_{seed}.log")
            runs.append({"seed": seed, **npz_curve(path), "final_plan_error": plan_error})
    return runs


def collect_more(scratch: Path) -> dict:
    """
    e. Reacher, 40k steps, the sources benchmark's recipe (zoo_runs/sources/reacher): lambda 1e-3 beside the benchmark's
    UDPO (the preset's lambda 1e-2) and SAC + HER; f. Maze2D, 20k steps, uniform-goal training, far-goal evaluation:
    lambda 1e-3 beside the benchmark's UDPO (the preset's 0.1) and SAC + HER.
    """
    tasks: dict = {}
    for env_id, folder, preset in (
        ("Pilot/Reacher-v0", "reacher_lam1e-3", "0.01"),
        ("Pilot/Maze2D-v0", "maze2d_lam1e-3", "0.1"),
    ):
        summary = SOURCES / f"source-{env_id.split('/')[-1].removesuffix('-v0').lower()}/summary.json"
        runs = scratch_seeds(scratch / folder, env_id)
        tasks[env_id] = {
            **({"UDPO lambda 0.001": runs} if runs else {}),
            f"UDPO lambda {preset} (preset, sources table)": summary_runs(summary, "UDPO+HER"),
            "SAC+HER (sources table)": summary_runs(summary, "SAC+HER"),
        }
    return tasks


def table(tasks: dict) -> str:
    lines = [
        "| task | method | seeds | steps to 90% IQM [95% CI] (reached) | final success IQM [CI] | area IQM [CI] "
        "| per seed: steps to 90% | final plan error per seed |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for task, methods in tasks.items():
        for i, (method, runs) in enumerate(methods.items()):
            if not runs:
                continue
            stats = method_statistics(runs)
            steps = stats["steps_to_90"]
            censored = steps["censored_at"]
            per_seed = []
            for run in runs:
                hit = [t for t, s in zip(run["timesteps"], run["success_rate"], strict=True) if s >= 0.9]
                per_seed.append(f"{hit[0] / 1000:g}k" if hit else "-")

            errors = [run.get("final_plan_error") for run in runs]
            plan_errors = " / ".join(f"{e:.3g}" for e in errors) if all(e is not None for e in errors) else ""

            def fmt(entry: dict, scale: float = 1.0, unit: str = "") -> str:
                value, (low, high) = entry["value"], entry["ci"]
                if scale != 1.0:
                    return f"{value / scale:.3g}{unit} [{low / scale:.3g}, {high / scale:.3g}]"
                return f"{value:.2f} [{low:.2f}, {high:.2f}]"

            lines.append(
                f"| {task if i == 0 else ''} | {method} | {stats['seeds']} | {fmt(steps, 1000, 'k')} "
                f"({steps['reached']}/{stats['seeds']}, censored at {censored / 1000:g}k) | {fmt(stats['final_success'])} | "
                f"{fmt(stats['area'])} | {' / '.join(per_seed)} | {plan_errors} |"
            )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scratch", default=None)
    parser.add_argument("--add", default=None)
    parser.add_argument("--add-high-dim", nargs=2, metavar=("ROOT", "COEF"), help="high_dim.py's --root and one --coefs")
    args = parser.parse_args()
    path = HERE / "curves.json"
    if args.scratch:
        path.write_text(json.dumps(collect(Path(args.scratch)), indent=1))
    if args.add:
        path.write_text(json.dumps({**json.loads(path.read_text()), **collect_more(Path(args.add))}, indent=1))
    if args.add_high_dim:
        tasks = json.loads(path.read_text())
        add_high_dim(tasks, Path(args.add_high_dim[0]), args.add_high_dim[1])
        path.write_text(json.dumps(tasks, indent=1))
    print(table(json.loads(path.read_text())))


if __name__ == "__main__":
    main()
