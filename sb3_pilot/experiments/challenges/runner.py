"""Run a challenge for several seeds and write its ``summary.json``."""

from __future__ import annotations

import json
import os
import shutil
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import torch as th

try:
    import fcntl
except ImportError:  # Windows: no advisory locks (side-by-side runners there rely on the read before each write)
    fcntl = None  # type: ignore[assignment]

from sb3_pilot.experiments.challenges.backends import BACKENDS, StageTask, run_local, run_ray
from sb3_pilot.experiments.challenges.controller import ControllerEvaluation
from sb3_pilot.experiments.challenges.definitions import BUDGET_CHALLENGES, BUDGETS, CHALLENGES, HER, Challenge, at_budget
from sb3_pilot.experiments.challenges.display import RunDisplay, stage_name
from sb3_pilot.experiments.challenges.records import config_differences
from sb3_pilot.experiments.challenges.stages import (
    PROGRESS_CSV,
    STAGE_COMMAND,
    STAGE_LOG,
    STAGE_MARKER,
    STAGE_STARTED,
    Budget,
    Stage,
    StageContext,
    ZooTrain,
    config_hash,
    portable,
)
from sb3_pilot.experiments.statistics import MIN_SEEDS, aggregate_name, format_seeds, summary_statistics
from sb3_pilot.experiments.zoo import hyperparams_dir

#: Success rates whose first crossing the summary reports (``steps_to_50``, ``steps_to_90``).
THRESHOLDS = (0.5, 0.9)
SUMMARY = "summary.json"
#: The stage in which a challenge trains its source (the task it transfers from), whose own learning the summary
#: records per seed (:func:`source_learning`).
SOURCE_STAGE = "source"
#: A source "learned" its task when the success rate of its last evaluation reaches this.
SOURCE_LEARNED = 0.5


def steps_to(timesteps: Sequence[int], success_rate: Sequence[float]) -> dict[str, int | None]:
    """
    :return: for each of :data:`THRESHOLDS`, the first evaluated env step whose success rate reaches it (None: never)
    """
    return {
        f"steps_to_{round(100 * threshold)}": next(
            (int(step) for step, rate in zip(timesteps, success_rate, strict=True) if rate >= threshold), None
        )
        for threshold in THRESHOLDS
    }


def upstream(challenge: Challenge, stage_name: str) -> set[str]:
    """
    :param challenge: the challenge
    :param stage_name: one of its stages
    :return: the names of the stages it reads from, directly or through others
    """
    by_name = {stage.name: stage for stage in challenge.stages}
    found: set[str] = set()
    todo = list(by_name[stage_name].needs)
    while todo:
        name = todo.pop()
        if name not in found:
            found.add(name)
            todo.extend(by_name[name].needs if name in by_name else ())
    return found


def count_sources(
    challenge: Challenge, method_stage: str, stages: dict[str, dict[str, Any]], seeds: Sequence[int]
) -> int | None:
    """
    The number of distinct sources a stage's seeds read from: the stages without inputs that it reads from, directly or
    through others (one trained per seed, or one shipped file for every seed), told apart by their configuration hash.

    :param challenge: the challenge
    :param method_stage: the stage's name (a compared method's)
    :param stages: ``summary.json``'s ``stages`` (or the stage markers) by ``seed_<k>/<stage>``, with ``config_hash``
    :param seeds: its seeds
    :return: 0 for a stage that reads from none; None where the challenge has no such stage or a source is not recorded
    """
    by_name = {stage.name: stage for stage in challenge.stages}
    if method_stage not in by_name:
        return None
    roots = {name for name in upstream(challenge, method_stage) if name not in by_name or not by_name[name].needs}
    if not roots:
        return 0
    sources = {tuple(stages.get(f"seed_{seed}/{root}", {}).get("config_hash") for root in sorted(roots)) for seed in seeds}
    return None if any(None in hashes for hashes in sources) else len(sources)


def mean_curve(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """
    :param runs: runs with ``timesteps`` and ``success_rate`` (and ``final_distance``)
    :return: their mean success rate (and final distance, where every run records it) over the evaluations they all
        have, with its steps to :data:`THRESHOLDS`
    """
    n_points = min(len(run["timesteps"]) for run in runs)
    timesteps = runs[0]["timesteps"][:n_points]
    mean: dict[str, Any] = {"timesteps": timesteps}
    mean["success_rate"] = np.mean([run["success_rate"][:n_points] for run in runs], axis=0).tolist()
    mean.update(steps_to(timesteps, mean["success_rate"]))
    if all(len(run.get("final_distance", ())) >= n_points for run in runs):
        mean["final_distance"] = np.mean([run["final_distance"][:n_points] for run in runs], axis=0).tolist()
    return mean


def source_learning(
    challenge: Challenge, seeds: Sequence[int], out_dir: Path, markers: dict[str, dict[str, Any]]
) -> dict[str, Any] | None:
    """
    How the challenge's trained source (its :class:`ZooTrain` stage :data:`SOURCE_STAGE`) learned its own task, per
    seed: the success rate of its last evaluation, its steps to :data:`THRESHOLDS` and whether it learned (the last
    success rate at least :data:`SOURCE_LEARNED`), from its ``evaluations.npz`` or, where its models are gone, as
    an earlier ``summary.json`` recorded it (``recorded`` in its marker).

    :param challenge: the challenge
    :param seeds: its seeds
    :param out_dir: ``<root>/<challenge>``
    :param markers: stage markers (or ``summary.json``'s ``stages``) by ``seed_<k>/<stage>``, with ``config_hash``
    :return: ``stage``, ``env_id``, ``learned_at``, ``methods`` (those that read from it) and ``runs`` (per seed
        recorded, with the source's ``config_hash``); None where no method reads a trained source or no seed's
        source is recorded
    """
    source = next((stage for stage in challenge.stages if stage.name == SOURCE_STAGE), None)
    methods = [stage.method for stage in challenge.stages if stage.method and SOURCE_STAGE in upstream(challenge, stage.name)]
    if not isinstance(source, ZooTrain) or not methods:
        return None
    runs = []
    for seed in seeds:
        marker = markers.get(f"seed_{seed}/{SOURCE_STAGE}")
        if marker is None:
            continue
        run = marker.get("recorded")
        if run is None:
            try:
                timesteps, success_rate = source.curve(out_dir / "models" / f"seed_{seed}" / SOURCE_STAGE)
            except FileNotFoundError:  # its models are gone, and no summary recorded it
                continue
            run = {"seed": seed, "final_success": success_rate[-1], **steps_to(timesteps, success_rate)}
        learned = run["final_success"] >= SOURCE_LEARNED
        runs.append({**run, "learned": learned, "config_hash": marker["config_hash"]})
    if not runs:
        return None
    return {"stage": SOURCE_STAGE, "env_id": source.env_id, "learned_at": SOURCE_LEARNED, "methods": methods, "runs": runs}


def describe_source(source: dict[str, Any]) -> str:
    """
    :param source: ``summary.json``'s ``source`` (:func:`source_learning`)
    :return: ``k of n seeds' sources learned``, the rule and the seeds whose source learned
    """
    learned = [run["seed"] for run in source["runs"] if run["learned"]]
    return (
        f"{len(learned)} of {len(source['runs'])} seeds' sources learned (the {source['stage']} stage's final success "
        f">= {source['learned_at']} on {source['env_id']}: seeds {learned})"
    )


def summarize(
    challenge: Challenge, budget: Budget, seeds: Sequence[int], out_dir: Path, markers: dict[str, dict[str, Any]]
) -> dict[str, Any]:
    """
    The challenge's results: success rate vs env steps on the target task, per compared method and seed, their
    mean over seeds, the steps to 50% / 90% success and the number of distinct sources its seeds read from
    (:func:`count_sources`); for a zero-shot method, the guidance horizon and switch rule; where methods read a trained
    source, how it learned its own task per seed (``source``, :func:`source_learning`). The compared methods that
    finished on a seed with stages still to run are kept apart (``partial_runs``, by ``seed_<k>/<stage>``), so that a
    later run on a fresh clone does not train them again; no statistic reads them.

    :param challenge: the challenge
    :param budget: the budget it ran at
    :param seeds: seeds whose stages all finished
    :param out_dir: ``<root>/<challenge>``
    :param markers: stage markers by ``seed_<k>/<stage>``
    :return: the summary (what ``summary.json`` holds)
    """
    methods: dict[str, Any] = {}
    by_name = {stage.name: stage for stage in challenge.stages}

    def method_run(stage: Stage, seed: int) -> dict[str, Any]:
        """A compared method's run on one seed: recorded, where its models are gone, else read from its folder."""
        recorded = markers.get(f"seed_{seed}/{stage.name}", {}).get("recorded")
        if recorded is not None:  # its models are gone: the run as an earlier summary.json recorded it
            return recorded
        stage_dir = out_dir / "models" / f"seed_{seed}" / stage.name
        timesteps, success_rate = stage.curve(stage_dir)
        run = {"seed": seed, "timesteps": timesteps, "success_rate": success_rate, **steps_to(timesteps, success_rate)}
        distances = stage.distances(stage_dir)
        return run if distances is None else {**run, "final_distance": distances}

    for stage in challenge.stages:
        if stage.method is None:
            continue
        runs = [method_run(stage, seed) for seed in seeds]
        sources = count_sources(challenge, stage.name, markers, seeds)
        mean = mean_curve(runs)
        methods[stage.method] = {"stage": stage.name, "env_id": stage.env_id, "runs": runs, "mean": mean, "sources": sources}
        if isinstance(stage, ControllerEvaluation) and stage.rule is not None:
            methods[stage.method]["guidance"] = stage.rule
        if isinstance(stage, ControllerEvaluation) and stage.compared_with is not None:
            methods[stage.method]["baseline"] = by_name[stage.compared_with].method
    stages: dict[str, Any] = {}
    for key, marker in markers.items():
        csv = out_dir / "models" / key / PROGRESS_CSV
        stages[key] = {
            "config_hash": marker["config_hash"],
            "wall_time_s": round(marker["wall_time_s"], 1),
            "config": marker["config"],
            "progress_csv": str(csv.relative_to(out_dir)) if csv.exists() else marker.get("progress_csv"),
            # a stage resumed from a checkpoint (its wall time: :func:`~.backends.stage_process_main`)
            **{key: marker[key] for key in ("resumed_from", "earlier_sittings_s") if key in marker},
        }
    summary = {
        "challenge": challenge.name,
        "description": challenge.description,
        "target_env": challenge.target_env,
        "budget": budget.name,
        "seeds": list(seeds),
        "thresholds": list(THRESHOLDS),
        "methods": methods,
        "stages": stages,
        "wall_time_s": round(sum(marker["wall_time_s"] for marker in markers.values()), 1),
    }
    # the finished methods of seeds with stages still to run: kept for resuming, out of the statistics
    partial = {}
    for key in markers:
        seed_name, name = key.split("/", 1)
        seed = int(seed_name.removeprefix("seed_"))
        if name in by_name and by_name[name].method is not None and seed not in seeds:
            partial[key] = method_run(by_name[name], seed)
    if partial:
        summary["partial_runs"] = partial
    source = source_learning(challenge, seeds, out_dir, markers)
    return summary if source is None else {**summary, "source": source}


def stage_graph(challenge: Challenge, seeds: Sequence[int]) -> dict[str, tuple[str, ...]]:
    """
    The stage graph of a challenge: for every seed and stage, ``seed_<k>/<stage>``, the keys of the stages it reads
    from (the same seed's). Stages of different seeds, and stages that read nothing (a baseline), are independent.

    :param challenge: the challenge
    :param seeds: the seeds
    :return: the graph, a stage after those it reads from (seed by seed, in the challenge's order)
    :raise ValueError: when a stage reads from a stage that is not before it in the challenge
    """
    graph: dict[str, tuple[str, ...]] = {}
    for seed in seeds:
        before: set[str] = set()
        for stage in challenge.stages:
            unknown = [need for need in stage.needs if need not in before]
            if unknown:
                raise ValueError(f"Stage {stage.name!r} of {challenge.name} reads from {unknown}, which are not before it.")
            graph[f"seed_{seed}/{stage.name}"] = tuple(f"seed_{seed}/{need}" for need in stage.needs)
            before.add(stage.name)
    return graph


def read_record(out_dir: Path) -> dict[str, Any]:
    """
    What a challenge's ``summary.json`` records (nothing where there is none).

    :param out_dir: ``<root>/<challenge>``
    :return: the summary, or one with no methods and no stages
    """
    path = out_dir / SUMMARY
    return json.loads(path.read_text()) if path.exists() else {"methods": {}, "stages": {}}


@contextmanager
def record_lock(out_dir: Path) -> Iterator[None]:
    """
    Hold a challenge folder's lock (an advisory ``flock`` on the folder itself, so no lock file is left behind; none
    on Windows) while reading ``summary.json`` and writing it back, so that another runner on the same folder cannot
    write between this one's read and its write.

    :param out_dir: ``<root>/<challenge>``, which exists
    """
    if fcntl is None:
        yield
        return
    descriptor = os.open(out_dir, os.O_RDONLY)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)
        yield
    finally:
        os.close(descriptor)  # releases the lock


def write_record(out_dir: Path, summary: dict[str, Any]) -> None:
    """
    Write a challenge's ``summary.json`` whole or not at all (a temporary file renamed over it), so that another
    runner on the same folder never reads half of it.

    :param out_dir: ``<root>/<challenge>``
    :param summary: the summary
    """
    temporary = out_dir / f".{SUMMARY}.{os.getpid()}"
    temporary.write_text(json.dumps(summary, indent=1))
    os.replace(temporary, out_dir / SUMMARY)


def recorded_runs(record: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """
    The runs a summary records, by ``seed_<k>/<stage>``: its methods', its trained source's own learning and its
    ``partial_runs``.

    :param record: a ``summary.json``
    :return: the runs
    """
    runs = {f"seed_{run['seed']}/{result['stage']}": run for result in record["methods"].values() for run in result["runs"]}
    if "source" in record:  # the trained source's own learning, kept as the methods' runs are
        runs.update({f"seed_{run['seed']}/{record['source']['stage']}": run for run in record["source"]["runs"]})
    runs.update(record.get("partial_runs", {}))  # methods finished on seeds with stages still to run
    return runs


def keep_earlier(summary: dict[str, Any], record: dict[str, Any], keys: Sequence[str]) -> dict[str, Any]:
    """
    A summary with what an earlier one recorded of the stages a run did not cover (``--stages``, fewer ``--seeds``):
    their stage records, and their runs in ``partial_runs`` (out of the statistics), so that a later run over them
    finds them finished where their hashes still match, instead of training them again.

    :param summary: the run's summary (:func:`summarize`)
    :param record: the ``summary.json`` on disk (:func:`read_record`, read before each write)
    :param keys: the run's stages, ``seed_<k>/<stage>``
    :return: the summary, with the earlier records of the other stages
    """
    covered = set(keys) | set(summary["stages"])
    stages = {key: entry for key, entry in record["stages"].items() if key not in covered}
    if not stages:
        return summary
    runs = {key: run for key, run in recorded_runs(record).items() if key in stages}
    partial = {**summary.get("partial_runs", {}), **runs}
    return {**summary, "stages": {**summary["stages"], **stages}, **({"partial_runs": partial} if partial else {})}


def check_recipe(challenge: Challenge, budget: Budget) -> str | None:
    """
    The recipe the challenge's zoo stages read at this budget (:attr:`Challenge.recipe`), checked before any work.

    :param challenge: the challenge
    :param budget: the budget
    :return: the recipe folder's name, or None where the budget reads no recipe or the challenge names none
    :raise ValueError: for a recipe that is no folder of the budget's ``hyperparams/`` (naming those there)
    """
    if not budget.recipes or challenge.recipe is None:
        return None
    folder = hyperparams_dir() / budget.conf_dir
    if not (folder / challenge.recipe).is_dir():
        names = sorted(path.name for path in folder.iterdir() if path.is_dir())
        raise ValueError(
            f"{challenge.name}: no recipe {challenge.recipe!r} in hyperparams/{budget.conf_dir} (its recipes: "
            f"{', '.join(names)})."
        )
    return challenge.recipe


def context_kwargs(challenge: Challenge, budget: Budget, steps: dict[str, int] | None = None) -> dict[str, Any]:
    """
    The budget's arguments of :class:`StageContext` for a challenge: the budget, the stages' env steps (the
    challenge's at this budget, ``steps`` over them) and the recipe it reads (:func:`check_recipe`).
    """
    stage_steps = {**challenge.steps.get(budget.name, {}), **(steps or {})}
    return {"budget": budget, "steps": stage_steps, "recipe": check_recipe(challenge, budget)}


def stage_tasks(challenge: Challenge, seeds: Sequence[int], out_dir: Path, ctx_kwargs: dict[str, Any]) -> dict[str, StageTask]:
    """
    Every stage of every seed with its configuration as stored (:func:`portable`) and its hash (from those of the
    stages it reads from), by ``seed_<k>/<stage>``, a stage after those it reads from.

    :param challenge: the challenge
    :param seeds: the seeds
    :param out_dir: ``<root>/<challenge>``
    :param ctx_kwargs: the other arguments of :class:`StageContext`
    """
    graph = stage_graph(challenge, seeds)
    tasks: dict[str, StageTask] = {}
    for seed in seeds:
        seed_dir = out_dir / "models" / f"seed_{seed}"
        ctx = StageContext(seed_dir, seed, **ctx_kwargs)
        ctx.outputs = {stage.name: stage.output(seed_dir / stage.name) for stage in challenge.stages}
        hashes: dict[str, str] = {}
        for stage in challenge.stages:
            key, stage_dir = f"seed_{seed}/{stage.name}", seed_dir / stage.name
            config = portable(stage.config(ctx, stage_dir), out_dir)
            hashes[stage.name] = digest = config_hash(config, [hashes[name] for name in stage.needs])
            tasks[key] = StageTask(key, stage, ctx, stage_dir, config, digest, graph[key])
    return tasks


def plan(
    challenge: Challenge, seeds: Sequence[int], out_dir: Path, ctx_kwargs: dict[str, Any]
) -> tuple[list[StageTask], dict[str, dict[str, Any]]]:
    """
    What is left to run: every stage's configuration and hash (from those of the stages it reads from), and the
    stages whose marker holds that hash (finished: skipped). A stage whose folder is gone (its models are gitignored:
    a fresh clone) but which the challenge's ``summary.json`` records with that hash is finished too (``recorded``:
    the summary keeps its run), unless a stage left to run reads from it.

    :param challenge: the challenge
    :param seeds: the seeds
    :param out_dir: ``<root>/<challenge>``
    :param ctx_kwargs: the other arguments of :class:`StageContext`
    :return: the stages to run (a stage after those it reads from) and the markers of the finished ones
    """
    graph = stage_graph(challenge, seeds)
    record = read_record(out_dir)
    runs = recorded_runs(record)
    todo: dict[str, StageTask] = {}
    finished: dict[str, dict[str, Any]] = {}
    for key, task in stage_tasks(challenge, seeds, out_dir, ctx_kwargs).items():
        stage, stage_dir, digest = task.stage, task.stage_dir, task.digest
        marker_path = stage_dir / STAGE_MARKER
        recorded = record["stages"].get(key, {})
        if marker_path.exists():
            marker = json.loads(marker_path.read_text())
            if marker["config_hash"] == digest:
                finished[key] = {**marker, "skipped": True}
                continue
        elif not stage_dir.exists() and recorded.get("config_hash") == digest and (stage.method is None or key in runs):
            finished[key] = {**recorded, "skipped": True, "from_summary": True, "recorded": runs.get(key)}
        todo[key] = task
    for key in reversed(graph):  # a recorded stage that a stage left to run reads from runs again
        if key in todo and key not in finished:
            for need in graph[key]:
                if finished.get(need, {}).get("from_summary"):
                    del finished[need]
    tasks = [task for key, task in todo.items() if key not in finished]
    for task in tasks:
        task.resume_from = resume_point(task)
    return tasks, finished


def resume_point(task: StageTask) -> int | None:
    """
    Where a stage left to run continues from: a zoo stage with resumable checkpoints
    (:attr:`~sb3_pilot.experiments.challenges.stages.ZooTrain.checkpoint_freq`) stopped with a checkpoint in its folder,
    started under the configuration it has now (its :data:`STAGE_STARTED`), goes on from that checkpoint.

    :param task: the stage
    :return: the checkpoint's env steps; None where the stage starts over
    """
    stage, started = task.stage, task.stage_dir / STAGE_STARTED
    if not isinstance(stage, ZooTrain) or not stage.checkpoint_freq or not started.is_file():
        return None
    if json.loads(started.read_text()).get("config_hash") != task.digest:
        return None
    checkpoint = stage.checkpoint(task.stage_dir)
    return None if checkpoint is None else int(checkpoint["num_timesteps"])


def keep_sitting_logs(stage_dir: Path) -> None:
    """
    Before a stage resumes, keep the logs of the sitting that stopped (``stage.log`` and ``progress.csv``, which the
    resumed process writes anew) beside it as ``stage.<n>.log`` and ``progress.<n>.csv``, ``n`` counting the sittings.

    :param stage_dir: the stage's folder
    """
    log = stage_dir / STAGE_LOG
    sitting = 1 + len(list(stage_dir.glob(f"{log.stem}.*{log.suffix}")))
    for path in (log, stage_dir / PROGRESS_CSV):
        if path.exists():
            path.rename(path.with_name(f"{path.stem}.{sitting}{path.suffix}"))


def run_challenge(
    name: str | Challenge,
    budget: str | Budget = "smoke",
    seeds: Sequence[int] = (0,),
    root: str | Path = "runs",
    steps: dict[str, int] | None = None,
    progress: bool | None = None,
    verbose: int = 0,
    jobs: int = 1,
    backend: str = "local",
    ray_address: str | None = None,
    threads: int = 1,
    keep_going: bool = False,
    dry_run: bool = False,
) -> dict[str, Any]:
    """
    Run (or resume) a challenge: every stage for every seed, each in a process of its own (its output in
    ``stage.log`` in its folder, a zoo stage's command line in ``command.txt``), a stage once the stages it reads from
    have finished; then write ``summary.json`` (also whenever all the stages of a seed have finished, so a long run
    shows its results as they come). A stage stopped before it finished starts over, but a zoo stage with resumable
    checkpoints, which goes on from its last (:func:`resume_point`; the earlier sittings' logs kept beside it,
    :func:`keep_sitting_logs`). The summary does not depend on the backend nor on ``jobs``. While it runs, it
    shows the stages started and finished and, on a terminal, a live table of the running stages' env steps
    (:mod:`~sb3_pilot.experiments.challenges.display`).

    :param name: a key of :data:`~sb3_pilot.experiments.challenges.CHALLENGES` (its stages at ``budget``:
        :func:`~sb3_pilot.experiments.challenges.definitions.at_budget`), or a :class:`Challenge`, run as it is
    :param budget: a key of :data:`~sb3_pilot.experiments.challenges.BUDGETS` or a custom :class:`Budget`; a budget of
        :data:`~sb3_pilot.experiments.challenges.definitions.BUDGET_CHALLENGES` runs only the challenges that have
        steps at it
    :param seeds: the seeds
    :param root: output root; the challenge writes into ``<root>/<name>/``
    :param steps: env steps per stage, overriding the budget's (e.g. the demo's)
    :param progress: the live table (None: when stdout is a terminal); False: plain lines
    :param verbose: 1 lets the zoo and SB3 print their logs (in the stages' logs)
    :param jobs: ``local`` backend: how many stages may run at once on this machine
    :param backend: ``local`` (this machine, ``jobs`` processes) or ``ray`` (every stage a Ray task)
    :param ray_address: ``ray`` backend: the cluster's address (None: a running Ray, or a local one started here)
    :param threads: torch threads of each stage's process (the CPUs a Ray task declares)
    :param keep_going: after a stage fails, go on with the stages that do not read from it (other seeds' stages,
        baselines); otherwise no stage starts after a failure. Either way the stages running finish and are recorded.
    :param dry_run: print what would run (each stage's command) and what is finished (:func:`format_plan`), and
        return without running or writing anything
    :return: the summary; with ``dry_run``, ``to_run`` and ``finished``, the stages' keys
    :raise StageFailed: once the stages running have finished, when a stage failed (its name and its log's tail)
    :raise ValueError: before any work, for bad input (an unknown challenge or budget, a budget the challenge does not
        run at, ...)
    """
    if isinstance(budget, str) and budget not in BUDGETS:
        raise ValueError(f"Unknown budget {budget!r}, choose one of {list(BUDGETS)}.")
    budget = BUDGETS[budget] if isinstance(budget, str) else budget
    if isinstance(name, Challenge):
        challenge = name
    elif name in CHALLENGES:
        challenge = at_budget(CHALLENGES[name], budget.name)
    else:
        raise ValueError(f"Unknown challenge {name!r}, choose one of {sorted(CHALLENGES)}.")
    if budget.name in BUDGET_CHALLENGES and budget.name not in challenge.steps:
        raise ValueError(
            f"The {budget.name} budget runs {', '.join(BUDGET_CHALLENGES[budget.name])} only, with stages of their own "
            f"at it; {challenge.name} runs at {', '.join(name for name in BUDGETS if name not in BUDGET_CHALLENGES)}."
        )
    if backend not in BACKENDS:
        raise ValueError(f"Unknown backend {backend!r}, choose one of {list(BACKENDS)}.")
    if jobs < 1 or threads < 1:
        raise ValueError(f"jobs and threads must be at least 1, not {jobs} and {threads}.")
    seeds = list(seeds)
    if not seeds:
        raise ValueError("seeds is empty: a challenge needs at least one seed (e.g. seeds=[0]).")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds has repeated values: {seeds}.")
    if backend == "ray" and jobs != 1:
        raise ValueError("jobs is for the local backend: Ray runs as many stages at once as the cluster has CPUs.")
    out_dir = Path(root).resolve() / challenge.name
    th.set_num_threads(1)  # this process only waits for the stages' processes
    ctx_kwargs = {**context_kwargs(challenge, budget, steps), "verbose": verbose, "threads": threads}
    tasks, markers = plan(challenge, seeds, out_dir, ctx_kwargs)
    if dry_run:
        title = f"{challenge.name} ({budget.name} budget, seeds {seeds})"
        print(format_plan(title, tasks, markers, read_record(out_dir)))
        return {"to_run": [task.key for task in tasks], "finished": list(markers)}
    for task in tasks:  # interrupted, or configured differently: start over (a started stage is one with a log) ...
        if task.resume_from is not None:  # ... but a stage that goes on from its checkpoint
            keep_sitting_logs(task.stage_dir)
        elif task.stage_dir.exists():
            shutil.rmtree(task.stage_dir)

    keys = list(stage_graph(challenge, seeds))
    seed_keys = {seed: [key for key in keys if key.startswith(f"seed_{seed}/")] for seed in seeds}
    summarized: list[int] = []
    live = sys.stdout.isatty() if progress is None else progress
    display = RunDisplay(f"{challenge.name} {budget.name}", len(keys), live=live)

    def save(summary: dict[str, Any], write: bool = True) -> dict[str, Any]:
        """
        The summary with what this run does not cover (other stages or seeds) as recorded now, read and written
        under the folder's lock: another runner on other seeds of the same folder (``--seeds 3-5`` beside
        ``--seeds 0-2``) may have recorded its stages since this one began.
        """
        with record_lock(out_dir):
            summary = keep_earlier(summary, read_record(out_dir), keys)
            if write:
                write_record(out_dir, summary)
        return summary

    def write_summary() -> dict[str, Any]:
        """The summary of the seeds whose stages have all finished (all of them at the end)."""
        done = [seed for seed in seeds if all(key in markers for key in seed_keys[seed])]
        if not done:
            return {}
        summary = summarize(challenge, budget, done, out_dir, {key: markers[key] for key in keys if key in markers})
        summary = save(summary, write=done != summarized)
        summarized[:] = done
        return summary

    def on_start(task: StageTask) -> None:
        total = task.stage.env_steps(task.ctx) if isinstance(task.stage, ZooTrain) else None
        display.started(task.key, task.stage.describe(task.ctx, task.stage_dir), task.stage_dir, total)

    def on_finish(task: StageTask, marker: dict[str, Any]) -> None:
        markers[task.key] = {**marker, "skipped": False}
        display.finished(task.key, marker["wall_time_s"])
        write_summary()

    with display:
        for key, marker in markers.items():
            where = ", recorded in summary.json (its models are gone)" if marker.get("from_summary") else ""
            display.skipped(f"{stage_name(key)}: done ({marker['wall_time_s']:.0f} s){where}, skipped")
        out_dir.mkdir(parents=True, exist_ok=True)
        if markers:
            write_summary()
        where = f"Ray ({ray_address or 'local'})" if backend == "ray" else f"{jobs} job{'s' * (jobs > 1)}"
        if tasks:
            models = out_dir / "models"
            shown = models.relative_to(Path.cwd()) if models.is_relative_to(Path.cwd()) else models
            display.print(
                f"{len(tasks)} stage{'s' * (len(tasks) > 1)} to run, {where}, {threads} thread(s) each; "
                f"their {STAGE_LOG} and {STAGE_COMMAND} in {shown}/seed_<k>/<stage>/"
            )
        if backend == "ray":
            run_ray(tasks, ray_address, on_start, on_finish, display.tick, display.failed, keep_going)
        else:
            run_local(tasks, jobs, on_start, on_finish, display.tick, display.failed, keep_going)
    summary = write_summary()
    if len(seeds) >= MIN_SEEDS:  # the rliable statistics (seconds of bootstrap), as ``pairs`` writes them
        summary["statistics"] = summary_statistics(summary, HER)
    summary = save(summary)  # the statistics took seconds: read again what another runner may have recorded
    display.print("done")
    print(format_table(summary))
    others = sorted({int(key.split("/")[0].removeprefix("seed_")) for key in summary.get("partial_runs", {})} - set(seeds))
    if others:  # a run of some seeds: the others' finished runs are kept, out of this table and its statistics
        every = ",".join(map(str, sorted({*seeds, *others})))
        print(
            f"Finished runs of other seeds ({', '.join(map(str, others))}) are kept in summary.json's partial_runs, out "
            f"of this table: --seeds {every} summarizes them all (their finished stages are not trained again)."
        )
    return summary


def format_plan(
    title: str, tasks: Sequence[StageTask], finished: dict[str, dict[str, Any]], record: dict[str, Any] | None = None
) -> str:
    """
    What a run would do (``--dry-run``): the stages finished (recorded in ``summary.json`` where their models are
    gone), then those to run, each with what it does (and the checkpoint it resumes from), for a zoo stage its command
    line and, for one that a record (its marker, else ``summary.json``) holds under another configuration, the fields
    that differ (:func:`~sb3_pilot.experiments.challenges.records.config_differences`).

    :param title: the first line's start
    :param tasks: the stages to run (:func:`plan`)
    :param finished: the markers of the finished stages (:func:`plan`)
    :param record: the challenge's ``summary.json`` (:func:`read_record`), for what differs from it
    """
    lines = [f"{title}: {len(tasks)} stage{'s' * (len(tasks) != 1)} to run, {len(finished)} finished"]
    for key, marker in finished.items():
        where = "; recorded in summary.json, its models gone" if marker.get("from_summary") else ""
        lines.append(f"  done  {stage_name(key)} ({marker['wall_time_s']:.0f} s{where})")
    for task in tasks:
        resumes = "" if task.resume_from is None else f", resumed from its checkpoint at {task.resume_from} env steps"
        lines.append(f"  run   {stage_name(task.key)}: {task.stage.describe(task.ctx, task.stage_dir)}{resumes}")
        if isinstance(task.stage, ZooTrain):
            lines.append(f"        {task.stage.command(task.ctx, task.stage_dir, resume=task.resume_from is not None)}")
        marker_path = task.stage_dir / STAGE_MARKER
        recorded = (record or {}).get("stages", {}).get(task.key)
        recorded = json.loads(marker_path.read_text()) if marker_path.exists() else recorded
        if recorded is not None and "config" in recorded and recorded.get("config_hash") != task.digest:
            differences = config_differences(recorded["config"], task.config) or [
                "none in its own configuration, but its config_hash (edited by hand, or a stage it reads from differs)"
            ]
            lines.append(f"        recorded with another configuration: {'; '.join(differences)}")
    return "\n".join(lines)


def format_table(summary: dict[str, Any]) -> str:
    """
    A markdown table of a summary: seeds (and distinct sources) per method, final success (mean [min, max] over
    seeds), steps to 50% / 90% of the mean curve and, when the summary has its ``statistics`` (3 seeds or more), the
    IQM of the area under the success curve (the mean, where the IQM cuts none) with its 95% interval and the verdict
    against SAC+HER (or the baseline the verdict names). Where the methods read a trained source (``source``) that
    learned on some seeds but not all, their rows again over those seeds only, against SAC+HER's every seed: a subset
    chosen after the fact (at most "a hint"); below the table, how many seeds' sources learned.
    """
    statistics = summary.get("statistics")
    lines = [
        f"{summary['challenge']} ({summary['budget']} budget, seeds {summary['seeds']}) on {summary['target_env']}",
        "| method | seeds (sources) | env steps | final success, mean [min, max] | steps to 50% | steps to 90% |"
        + (" area, IQM [95% CI] | verdict |" if statistics else ""),
        "|---|---|---|---|---|---|" + ("---|---|" if statistics else ""),
    ]

    baselines = {HER, *(result["baseline"] for result in summary["methods"].values() if "baseline" in result)}

    def row(method: str, label: str, runs: list[dict[str, Any]], sources: int | None, stats: dict[str, Any] | None) -> str:
        """A method's row over ``runs``, with its statistics (``{"methods", "comparisons"}``) if any."""
        finals = [run["success_rate"][-1] for run in runs]
        mean = mean_curve(runs)
        line = (
            f"| {label} | {format_seeds(len(runs), sources)} | {mean['timesteps'][-1]} | "
            f"{np.mean(finals):.2f} [{min(finals):.2f}, {max(finals):.2f}] | "
            f"{mean['steps_to_50'] or '-'} | {mean['steps_to_90'] or '-'} |"
        )
        if stats is None:
            return line + (" - | - |" if statistics else "")
        area = stats["methods"][method]["area"]
        comparison = stats["comparisons"].get(method)
        aggregate = "mean " if aggregate_name(len(runs)) == "mean" else ""
        line += f" {aggregate}{area['value']:.2f} [{area['ci'][0]:.2f}, {area['ci'][1]:.2f}] | "
        return line + f"{comparison['verdict'] if comparison else 'baseline' if method in baselines else '-'} |"

    for method, result in summary["methods"].items():
        lines.append(row(method, method, result["runs"], result.get("sources"), statistics))
    source = summary.get("source")
    if source is None:
        return "\n".join(lines)
    learned = {run["seed"] for run in source["runs"] if run["learned"]}
    split = statistics.get("source_learned") if statistics else None
    if 0 < len(learned) < len(source["runs"]):
        sources = len({run["config_hash"] for run in source["runs"] if run["learned"]})
        for method in source["methods"]:
            runs = [run for run in summary["methods"][method]["runs"] if run["seed"] in learned]
            label = f"{method}, only the seeds whose source learned (a subset chosen after the fact: at most a hint)"
            lines.append(row(method, label, runs, sources, split))
    return "\n".join([*lines, f"Sources: {describe_source(source)}."])
