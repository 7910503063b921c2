"""
The paper's claim about sources: UDPO learns the source tasks about as fast as HER. On each of the five source tasks,
UDPO + HER and SAC + HER train with the same budget and seeds, as two stages of the challenge runner (the zoo with this
package's YAML, resumable, ``summary.json`` and ``success.png`` per task), then a table with a verdict per task::

    python -m benchmarks.sources --budget cpu --seeds 0 1 2 --jobs 1 --root zoo_runs/sources \
        --tasks Pilot/Maze2D-v0
    python -m benchmarks.sources --table-only --root zoo_runs/sources

The Fetch tasks use RL-Zoo's FetchReach settings with VecNormalize for both methods (the recipe
``hyperparams/cpu/fetch/``, as the Fetch challenges), Reacher the same with one env
(:data:`RECIPES`, :data:`CPU_STEPS`), the others their
``hyperparams/<budget>`` entries; Maze2D trains on uniform starts and goals and is evaluated on the far goal
(:data:`TRAIN_ENV_KWARGS`, :data:`EVAL_ENV_KWARGS`).
The table (``ROOT/table.md``, every task with a summary under ROOT) gives per task and method the ``rliable`` IQM over
seeds and stratified-bootstrap 95% interval of the steps to 50% / 90% success, the final success and the area under
the success curve (:mod:`sb3_pilot.experiments.statistics`), and :func:`verdict`: UDPO "as fast as HER" when its IQM
steps to 90% are at most 1.1x SAC + HER's.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from sb3_pilot.experiments.challenges import Challenge, ZooTrain, run_challenge
from sb3_pilot.experiments.statistics import MIN_SEEDS, REPS, compare, method_statistics

SOURCE_TASKS = ("Pilot/FetchReach-v0", "Pilot/FetchPush-v0", "Pilot/Reacher-v0", "Pilot/Maze2D-v0", "Pilot/PointLocomotion-v0")
UDPO_HER, SAC_HER = "UDPO+HER", "SAC+HER"
#: Smoke steps: past the first episodes of every env, so that HER samples (PointLocomotion: 4 envs x 500 steps).
SMOKE_STEPS = {"Pilot/FetchPush-v0": 500, "Pilot/PointLocomotion-v0": 2100}
#: Task options of the training env, per task (the zoo's ``--env-kwargs``, every budget): Maze2D trains on starts
#: and goals uniform over the maze, as the Maze-Car and zero-shot Ant-Maze sources do; on the far goal alone
#: neither method reached the far end of the U in 20k steps (3 seeds each, zoo_runs/sources/old-recipe).
TRAIN_ENV_KWARGS: dict[str, dict[str, Any]] = {"Pilot/Maze2D-v0": {"goal_distribution": "uniform"}}
#: Task options of the evaluation env: Maze2D is evaluated on the far goal (the paper's hard case) only.
EVAL_ENV_KWARGS: dict[str, dict[str, Any]] = {"Pilot/Maze2D-v0": {"goal_distribution": "far"}}
#: Recipe (folder of ``hyperparams/cpu/``) read at the smoke and cpu budgets, per task, both methods alike:
#: RL-Zoo's FetchReach settings with VecNormalize on the Fetch tasks (as the Fetch challenges) and on Reacher, there with
#: one env (one gradient step per env step). Reacher's recipe and budget were sized from SAC + HER's probes alone,
#: before any UDPO run (zoo_runs/sources/reacher): the preset's 4 envs (one gradient step per 4 env steps), gamma 0.99
#: and lr 3e-4 reached 0.00-0.20 success in 50k steps. FetchPush's is ``fetch_push`` (the High-Dim Push
#: challenge's too): one env, tau 0.05, 256x256 networks, a target entropy of 0 and a 50k-step random warm-up, sized
#: from SAC + HER's runs (zoo_runs/sources/fetchpush), UDPO with the linearised entropy term and lambda 1e-4.
RECIPES: dict[str, str] = {"Pilot/FetchReach-v0": "fetch", "Pilot/FetchPush-v0": "fetch_push", "Pilot/Reacher-v0": "reacher"}
#: Env steps at the cpu budget where not the YAML's ``n_timesteps``, per task.
CPU_STEPS = {"Pilot/Reacher-v0": 40_000, "Pilot/FetchPush-v0": 150_000}
#: UDPO keeps pace with HER when its IQM steps to 90% success are at most this many times SAC + HER's (issue 21).
AS_FAST = 1.1


def source_challenge(env_id: str) -> Challenge:
    """UDPO + HER beside SAC + HER on ``env_id``, two independent stages per seed (same task options and settings)."""
    name = "source-" + env_id.split("/")[-1].removesuffix("-v0").lower()
    smoke = SMOKE_STEPS.get(env_id, 300)
    env_kwargs, eval_env_kwargs = TRAIN_ENV_KWARGS.get(env_id, {}), EVAL_ENV_KWARGS.get(env_id, {})
    return Challenge(
        name,
        f"UDPO + HER vs SAC + HER on the source task {env_id}, same budget",
        env_id,
        tuple(
            ZooTrain(stage, algo, env_id, conf, method=method, env_kwargs=env_kwargs, eval_env_kwargs=eval_env_kwargs)
            for stage, algo, conf, method in (("udpo", "udpo", "udpo.yml", UDPO_HER), ("her", "sac", "sac.yml", SAC_HER))
        ),
        steps={
            "smoke": {"udpo": smoke, "her": smoke},
            **({"cpu": {"udpo": CPU_STEPS[env_id], "her": CPU_STEPS[env_id]}} if env_id in CPU_STEPS else {}),
        },
        recipe=RECIPES.get(env_id),
    )


def verdict(udpo: dict[str, Any], her: dict[str, Any], ratio: dict[str, Any] | None = None) -> str:
    """
    Whether UDPO learned as fast as HER (issue 21's rule): "as fast as HER" when UDPO's IQM over seeds of the steps to
    90% success is at most :data:`AS_FAST` times SAC + HER's, seeds that never reach 90% counted one evaluation
    interval past the budget (``censored_at``, as :func:`~sb3_pilot.experiments.statistics.run_scores`).

    :param udpo: UDPO + HER's :func:`~sb3_pilot.experiments.statistics.method_statistics`
    :param her: the same for SAC + HER
    :param ratio: the ratio's stratified-bootstrap interval (``compare``'s ``steps_to_90_ratio``), printed after it
    """
    udpo_steps, her_steps = udpo["steps_to_90"], her["steps_to_90"]
    seeds = min(udpo["seeds"], her["seeds"])
    if udpo_steps["reached"] == 0 and her_steps["reached"] == 0:
        return "neither reached 90% at this budget"
    value = udpo_steps["value"] / her_steps["value"]
    pace = "as fast as HER" if value <= AS_FAST else "slower than HER"
    times = f"{value:.2f}x HER's" + (f" [{ratio['ci'][0]:.2f}, {ratio['ci'][1]:.2f}]" if ratio else "")
    # a method that never reached 90% has the censored steps as its IQM: the ratio is then a bound
    if udpo_steps["reached"] == 0:
        text = f"{pace} (UDPO never reached 90%: IQM steps to 90% at least {times})"
    elif her_steps["reached"] == 0:
        text = f"{pace} (HER never reached 90%: IQM steps to 90% at most {times})"
    else:
        text = f"{pace} (IQM steps to 90% {times})"
    return text if seeds >= MIN_SEEDS else f"too few seeds ({seeds}) for a verdict: {text}"


def _estimate(entry: dict[str, Any]) -> str:
    """``value [low, high]`` of a statistic."""
    low, high = entry["ci"]
    return f"{entry['value']:.2f} [{low:.2f}, {high:.2f}]"


def _steps(entry: dict[str, Any], seeds: int) -> str:
    """IQM of the steps to a success rate, its interval and how many seeds reached it (the others censored)."""
    if entry["reached"] == 0:
        return f"never (0/{seeds})"
    low, high = entry["ci"]
    return f"{entry['value']:.0f} [{low:.0f}, {high:.0f}] ({entry['reached']}/{seeds})"


def table(summaries: list[dict[str, Any]], reps: int = REPS) -> str:
    """
    A markdown table per task and method: the ``rliable`` IQM over seeds and stratified-bootstrap 95% interval of the
    steps to 50% / 90% success (seeds reaching it; the others counted at ``censored_at``), the final success and the
    area under the success curve (:func:`~sb3_pilot.experiments.statistics.method_statistics`), and :func:`verdict`
    with the ratio's 95% interval (:func:`~sb3_pilot.experiments.statistics.compare`).

    :param summaries: the tasks' ``summary.json``
    :param reps: bootstrap replications
    """
    lines = [
        "| task (seeds) | method | env steps | steps to 50%, IQM [95% CI] (seeds reaching it) | steps to 90% | "
        "final success, IQM [95% CI] | area under the success curve, IQM [95% CI] | verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for summary in summaries:
        methods = summary["methods"]
        stats = {method: method_statistics(methods[method]["runs"], reps=reps) for method in (UDPO_HER, SAC_HER)}
        ratio = compare(methods[UDPO_HER]["runs"], methods[SAC_HER]["runs"], reps=reps)["steps_to_90_ratio"]
        task = f"{summary['target_env']} ({len(summary['seeds'])})"
        for method in (UDPO_HER, SAC_HER):
            entry = stats[method]
            lines.append(
                f"| {task} | {method} | {methods[method]['mean']['timesteps'][-1]} | "
                f"{_steps(entry['steps_to_50'], entry['seeds'])} | {_steps(entry['steps_to_90'], entry['seeds'])} | "
                f"{_estimate(entry['final_success'])} | {_estimate(entry['area'])} | "
                f"{verdict(stats[UDPO_HER], stats[SAC_HER], ratio) if method == UDPO_HER else ''} |"
            )
            task = ""
    return "\n".join(lines)


def task_summaries(root: str | Path) -> list[dict[str, Any]]:
    """The ``summary.json`` of every source task run under ``root`` (in :data:`SOURCE_TASKS`' order)."""
    paths = (Path(root) / source_challenge(env_id).name / "summary.json" for env_id in SOURCE_TASKS)
    return [json.loads(path.read_text()) for path in paths if path.is_file()]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.sources", description=__doc__)
    parser.add_argument("--budget", default="cpu")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--tasks", nargs="+", default=list(SOURCE_TASKS), choices=SOURCE_TASKS)
    parser.add_argument("--root", default="runs/sources")
    parser.add_argument("--jobs", type=int, default=1, help="stages at once (UDPO and HER of a seed run together)")
    parser.add_argument("--plot", action="store_true", help="write success.png per task")
    parser.add_argument("--table-only", action="store_true", help="train nothing: rebuild table.md from ROOT's summaries")
    parser.add_argument("--reps", type=int, default=REPS, help="bootstrap replications of the intervals")
    args = parser.parse_args(argv)
    for env_id in [] if args.table_only else args.tasks:
        challenge = source_challenge(env_id)
        run_challenge(challenge, args.budget, seeds=args.seeds, root=args.root, jobs=args.jobs)
        if args.plot:
            from sb3_pilot.experiments.plots import plot_challenge

            plot_challenge(Path(args.root) / challenge.name)
    # every task run under ROOT, not only those of this call
    text = table(task_summaries(args.root), args.reps)
    (Path(args.root) / "table.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
