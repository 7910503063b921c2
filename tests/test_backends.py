"""
The challenge runner's execution backends: the stage graph, ``--jobs N`` on this machine, Ray, failed stages.

The tiny stages here record when they ran; their processes import this module (``PYTHONPATH`` holds ``tests/``).
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import torch as th

from sb3_pilot.experiments.challenges import (
    CHALLENGES,
    Challenge,
    StageFailed,
    backends,
    only_stages,
    run_challenge,
    stage_graph,
)
from sb3_pilot.experiments.challenges.__main__ import main as challenges_main
from sb3_pilot.experiments.challenges.runner import record_lock
from sb3_pilot.experiments.challenges.stages import STAGE_LOG, STAGE_MARKER

TESTS = Path(__file__).parent


@dataclass(frozen=True)
class Sleep:
    """
    A tiny stage: writes its pid, prints ``lines`` lines, sleeps, and writes when it ran and with how many threads.

    :param wait_for: a stage of the same seed whose pid file it waits for before failing or sleeping (the pid is
        written first, so two stages may wait for each other)
    :param fail: raise instead of sleeping
    """

    name: str
    seconds: float
    needs: tuple[str, ...] = ()
    wait_for: str | None = None
    fail: bool = False
    lines: int = 3
    method = None

    def output(self, stage_dir: Path) -> Path:
        return stage_dir / "times.json"

    def config(self, ctx: Any, stage_dir: Path) -> dict[str, Any]:
        return {"seconds": self.seconds, "seed": ctx.seed, "needs": [str(ctx.outputs[need]) for need in self.needs]}

    def describe(self, ctx: Any, stage_dir: Path) -> str:
        return f"sleep {self.seconds} s"

    def run(self, ctx: Any, stage_dir: Path) -> None:
        start = time.time()
        (stage_dir / "pid").write_text(str(os.getpid()))
        for need in self.needs:
            assert ctx.outputs[need].exists(), need
        if self.wait_for is not None:
            other = ctx.seed_dir / self.wait_for / "pid"
            while not other.exists():
                time.sleep(0.05)
        for line in range(self.lines):
            print(f"{self.name} line {line}", flush=True)
        if self.fail:
            raise RuntimeError(f"{self.name} failed on purpose")
        time.sleep(self.seconds)
        times = {"start": start, "end": time.time(), "threads": th.get_num_threads(), "omp": os.environ["OMP_NUM_THREADS"]}
        self.output(stage_dir).write_text(json.dumps(times))


@dataclass(frozen=True)
class ZooLike(Sleep):
    """A :class:`Sleep` stage whose work ends normally on Ctrl-C, as the zoo's training does (it then saves the model)."""

    def run(self, ctx: Any, stage_dir: Path) -> None:
        (stage_dir / "pid").write_text(str(os.getpid()))
        with contextlib.suppress(KeyboardInterrupt):
            time.sleep(self.seconds)
        self.output(stage_dir).write_text("{}")


@dataclass(frozen=True)
class Scored(Sleep):
    """A tiny compared method: a :class:`Sleep` stage with a success curve, its seed's."""

    method: str = "scored"
    env_id = "none"

    def curve(self, stage_dir: Path) -> tuple[list[int], list[float]]:
        seed = json.loads((stage_dir / STAGE_MARKER).read_text())["config"]["seed"]
        return [10, 20], [0.0, seed / 10]

    def distances(self, stage_dir: Path) -> None:
        return None


@dataclass(frozen=True)
class Meanwhile(Scored):
    """A :class:`Scored` stage during which another runner of the same folder records its seeds: it puts the
    folder's ``other.json`` in place of its ``summary.json``."""

    def run(self, ctx: Any, stage_dir: Path) -> None:
        out_dir = ctx.seed_dir.parents[1]
        shutil.copy(out_dir / "other.json", out_dir / "summary.json")
        super().run(ctx, stage_dir)


def tiny(*stages: Sleep) -> Challenge:
    return Challenge("tiny", "tiny stages", "none", stages, steps={})


@pytest.fixture
def importable(monkeypatch: pytest.MonkeyPatch) -> None:
    """The stage processes (and Ray's workers) can import this module."""
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(TESTS), os.environ.get("PYTHONPATH")])))


def _times(run_dir: Path, key: str) -> dict[str, Any]:
    return json.loads((run_dir / "models" / key / "times.json").read_text())


def _summary_without_times(path: Path) -> dict[str, Any]:
    summary = json.loads(path.read_text())
    summary.pop("wall_time_s")
    for stage in summary["stages"].values():
        stage.pop("wall_time_s")
    return summary


def _dead(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


def test_stage_graphs() -> None:
    """Per seed: source -> (distillation ->) target; baselines and other seeds' stages depend on nothing."""
    transfer = {"source": (), "pilot": ("source",), "her": ()}
    bonus = {"source": (), "distill": ("source",), "pilot": ("distill",), "pilot_disp": ("distill",), "her": ()}
    expected = {
        "high-dim-action": transfer,
        "high-dim-action-push": transfer,
        "vec-to-image": bonus,
        "vec-to-image-reacher": bonus,
        "complex-morph": {**bonus, "mega": ()},
        "maze-car": {**bonus, "mega": ()},
        "wall-maze-car": {
            "teacher": (),
            "distill": ("teacher",),
            "pilot_disp": ("distill",),
            "her": (),
            "controller": (),
            "guided": ("distill", "controller"),
            "unguided": ("controller",),
        },
        "pointmaze-to-antmaze": {
            "teacher": (),
            "distill": ("teacher",),
            "controller": (),
            "chosen": ("controller",),
            "pilot": ("distill", "chosen"),
            "unguided": ("chosen",),
            "open_ground": ("chosen",),
        },
        "zero-shot-ant-maze": {
            "maze": (),
            "distill": ("maze",),
            "controller": (),
            "chosen": ("controller",),
            "pilot": ("distill", "chosen"),
            "unguided": ("chosen",),
            "her": (),
            "mega": (),
        },
    }
    # the literature's Ant: the same stages but the baselines trained on Ant-Maze
    zero_shot = expected["zero-shot-ant-maze"]
    expected["zero-shot-ant-maze-v1"] = {name: needs for name, needs in zero_shot.items() if name not in ("her", "mega")}
    for name, challenge in CHALLENGES.items():
        graph = stage_graph(challenge, [0, 1])
        keys = list(graph)
        for key, needs in graph.items():
            assert all(keys.index(need) < keys.index(key) for need in needs), (name, key)  # a stage after its needs
            assert all(need.split("/")[0] == key.split("/")[0] for need in needs)  # within its seed
        assert graph == {
            f"seed_{seed}/{stage}": tuple(f"seed_{seed}/{need}" for need in needs)
            for seed in (0, 1)
            for stage, needs in expected[name].items()
        }
    with pytest.raises(ValueError, match=r"reads from \['b'\], which are not before it"):
        stage_graph(tiny(Sleep("a", 0, needs=("b",)), Sleep("b", 0)), [0])


def test_jobs_run_independent_stages_together(tmp_path: Path, importable: None, capsys: pytest.CaptureFixture[str]) -> None:
    """--jobs 2 starts a stage and an independent one together, a dependent one after its source; --jobs 1 one by one."""
    challenge = tiny(Sleep("source", 2.0), Sleep("target", 0.1, needs=("source",)), Sleep("baseline", 2.0))
    run_challenge(challenge, seeds=[0], root=tmp_path / "two", jobs=2)
    out = capsys.readouterr().out
    assert "running: seed_0/source, seed_0/baseline]" in out
    run_dir = tmp_path / "two" / "tiny"
    source, target, baseline = (_times(run_dir, f"seed_0/{name}") for name in ("source", "target", "baseline"))
    assert source["start"] < baseline["end"] and baseline["start"] < source["end"]  # together
    assert target["start"] >= source["end"]
    for times in (source, target, baseline):  # each process got the threads it was given
        assert times["threads"] == 1 and times["omp"] == "1"
    assert "source line 2" in (run_dir / "models" / "seed_0" / "source" / STAGE_LOG).read_text()
    summary = json.loads((run_dir / "summary.json").read_text())
    assert list(summary["stages"]) == ["seed_0/source", "seed_0/target", "seed_0/baseline"]

    run_challenge(challenge, seeds=[0], root=tmp_path / "two", jobs=2)  # finished: every stage skipped
    assert capsys.readouterr().out.count("skipped") == 3

    run_challenge(challenge, seeds=[0], root=tmp_path / "one", jobs=1)
    run_dir = tmp_path / "one" / "tiny"
    times = sorted((_times(run_dir, f"seed_0/{name}") for name in ("source", "target", "baseline")), key=lambda t: t["start"])
    assert all(first["end"] <= second["start"] for first, second in itertools.pairwise(times))
    assert _summary_without_times(run_dir / "summary.json") == _summary_without_times(tmp_path / "two/tiny/summary.json")


@pytest.mark.parametrize("keep_going", [False, True])
def test_failed_stage_ends_the_run_once_the_running_ones_finish(
    tmp_path: Path, importable: None, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], keep_going: bool
) -> None:
    """
    The run ends with the failed stage's name and its log's tail, after the stage running beside it has finished (and
    is recorded); no stage starts after the failure, or with ``--keep-going`` those that do not read from it.
    """
    challenge = tiny(
        Sleep("slow", 3.0, wait_for="boom"),
        Sleep("boom", 0.0, wait_for="slow", fail=True, lines=40),
        Sleep("later", 0.0),
        Sleep("after", 0.0, needs=("boom",)),
    )
    monkeypatch.setitem(CHALLENGES, "tiny", challenge)
    with pytest.raises(SystemExit) as exit_info:
        challenges_main(["tiny", "--root", str(tmp_path), "--jobs", "2", *(["--keep-going"] * keep_going)])
    message, out = str(exit_info.value.code), capsys.readouterr().out
    assert "seed 0 boom: failed (exit status 1), log: " in out and "waiting for seed_0/slow to finish (Ctrl-C" in out
    not_run = "seed_0/after" if keep_going else "seed_0/later, seed_0/after"
    assert message.startswith(f"tiny: Stage seed_0/boom failed (exit status 1; not run: {not_run})")
    assert "RuntimeError: boom failed on purpose" in message and "boom line 39" in message
    assert "boom line 0\n" not in message  # the tail, not the whole log
    seed_dir = tmp_path / "tiny" / "models" / "seed_0"
    assert (seed_dir / "slow" / STAGE_MARKER).exists() and not (seed_dir / "boom" / STAGE_MARKER).exists()
    assert (seed_dir / "later" / STAGE_MARKER).exists() == keep_going
    assert not (seed_dir / "after").exists()


def test_an_interrupt_stops_the_running_stages(tmp_path: Path, importable: None) -> None:
    """
    Ctrl-C (here a KeyboardInterrupt raised by a timer once the stage's process runs) stops the running stage: no
    process is left behind.
    """
    stage_dir = tmp_path / "tiny" / "models" / "seed_0" / "slow"

    def interrupt(signum: int, frame: object) -> None:
        if not (stage_dir / "pid").exists():  # still starting (slow on a loaded machine): look again soon
            signal.setitimer(signal.ITIMER_REAL, 0.5)
            return
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGALRM, interrupt)
    signal.setitimer(signal.ITIMER_REAL, 1.0)
    start = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            run_challenge(tiny(Sleep("slow", 300.0)), seeds=[0], root=tmp_path)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
    assert time.monotonic() - start < 200
    assert _dead(int((stage_dir / "pid").read_text())) and not (stage_dir / STAGE_MARKER).exists()


def _gone(pid: int) -> bool:
    """The process has ended (a zombie not yet reaped counts as ended)."""
    try:
        return Path(f"/proc/{pid}/status").read_text().split("State:")[1].split()[0] == "Z"
    except (FileNotFoundError, ProcessLookupError):
        return True


def test_a_killed_runner_leaves_no_stage_behind(tmp_path: Path, importable: None) -> None:
    """
    A runner killed outright (SIGKILL: no handler of its runs): the stage it was running ends too (a thread of the
    stage's watches a pipe that only the runner holds open), although the fork server it was forked from lives on.
    """
    pid_file = tmp_path / "tiny" / "models" / "seed_0" / "slow" / "pid"
    code = (
        "from test_backends import Sleep, tiny; from sb3_pilot.experiments.challenges import run_challenge; "
        f"run_challenge(tiny(Sleep('slow', 300.0)), seeds=[0], root={str(tmp_path)!r})"
    )
    runner = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not (pid_file.exists() and pid_file.read_text()) and runner.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)
    assert runner.poll() is None and pid_file.exists(), "the stage did not start"
    stage = int(pid_file.read_text())
    runner.kill()
    runner.wait()
    deadline = time.monotonic() + 30
    while not _gone(stage) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _gone(stage), f"stage process {stage} outlived its runner"


def test_ctrl_c_at_a_terminal_records_no_stage_as_finished(tmp_path: Path, importable: None) -> None:
    """
    Ctrl-C at a terminal signals every process of the runner's group, its stages too. The zoo's training ends
    normally on it (it saves the model), so a stage that took it would be recorded as finished after part of its
    steps; stages leave it to their runner, which stops them: none is recorded, none is left.
    """
    stage_dir = tmp_path / "tiny" / "models" / "seed_0" / "slow"
    code = (  # Ctrl-C handled as at a terminal (a runner started in the background of a script ignores it)
        "import signal; signal.signal(signal.SIGINT, signal.default_int_handler); "
        "from test_backends import ZooLike, tiny; from sb3_pilot.experiments.challenges import run_challenge; "
        f"run_challenge(tiny(ZooLike('slow', 300.0)), seeds=[0], root={str(tmp_path)!r})"
    )
    runner = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    deadline = time.monotonic() + 120
    while not ((stage_dir / "pid").exists() and (stage_dir / "pid").read_text()) and time.monotonic() < deadline:
        assert runner.poll() is None, "the runner ended before its stage started"
        time.sleep(0.1)
    stage = int((stage_dir / "pid").read_text())
    os.killpg(runner.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the runner's whole group
    assert runner.wait(timeout=120) != 0
    assert not (stage_dir / STAGE_MARKER).exists() and not (stage_dir / "times.json").exists()
    assert _gone(stage), f"stage process {stage} outlived its runner"


def test_ctrl_c_as_a_stage_starts_stops_that_stage_too(
    tmp_path: Path, importable: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """
    Ctrl-C that comes while a stage's process is being started (forked, not yet among the running stages): the
    runner stops it with the others instead of leaving it running (and, as a child process, waited for at exit).
    """
    started: list[int] = []
    start_stage = backends.start_stage

    def start_then_ctrl_c(task: Any) -> Any:
        process = start_stage(task)
        started.append(process.process.pid)
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(1.0)  # the signal's handler runs here, before the runner has registered the process
        return process

    monkeypatch.setattr(backends, "start_stage", start_then_ctrl_c)
    # Ctrl-C handled as at a terminal (this process may have been started ignoring it: in the background of a script)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            run_challenge(tiny(Sleep("slow", 300.0)), seeds=[0], root=tmp_path)
        assert started and _gone(started[0]), "the stage started as Ctrl-C came was left running"
    finally:
        signal.signal(signal.SIGINT, previous)
        for pid in started:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)


def test_ray_backend_matches_serial(tmp_path: Path, importable: None, capsys: pytest.CaptureFixture[str]) -> None:
    """
    High-Dim-Action at the smoke budget, serially and on a local Ray cluster (2 CPUs, its independent stages side by
    side): one summary (but wall times). On Ray, a failed stage ends the run with its log's tail once the running
    task has finished; the task reading from it does not run.
    """
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install -e .[ray]): the Ray backend is untested")
    serial = run_challenge("high-dim-action", "smoke", seeds=[0], root=tmp_path / "serial")
    expected = _summary_without_times(tmp_path / "serial" / "high-dim-action" / "summary.json")

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        capsys.readouterr()
        on_ray = run_challenge("high-dim-action", "smoke", seeds=[0], root=tmp_path / "ray", backend="ray")
        out = capsys.readouterr().out
        assert "Ray (local)" in out and "seed 0 her: finished" in out
        assert on_ray["methods"] == serial["methods"]
        assert _summary_without_times(tmp_path / "ray" / "high-dim-action" / "summary.json") == expected

        challenge = tiny(
            Sleep("slow", 3.0, wait_for="boom"),
            Sleep("boom", 0.0, wait_for="slow", fail=True, lines=40),
            Sleep("after", 0.0, needs=("boom",)),
        )
        match = r"Stage seed_0/boom failed \(exit status 1 on .*; not run: seed_0/after\)"
        with pytest.raises(StageFailed, match=match) as error_info:
            run_challenge(challenge, seeds=[0], root=tmp_path / "fail", backend="ray")
        assert "boom line 39" in str(error_info.value) and "RuntimeError: boom failed on purpose" in str(error_info.value)
    finally:
        ray.shutdown()
    assert (tmp_path / "fail" / "tiny" / "models" / "seed_0" / "slow" / STAGE_MARKER).exists()  # it finished


def test_a_run_of_some_stages_keeps_the_others_recorded(
    tmp_path: Path, importable: None, capsys: pytest.CaptureFixture[str]
) -> None:
    """
    ``--stages`` or fewer ``--seeds`` on a run whose models are gone (a fresh clone) keep the earlier summary's records
    of the other stages (out of the statistics, which the run says, naming the seeds that summarize them all), so that
    the whole run afterwards trains nothing again.
    """
    challenge = tiny(Scored("a", 0.0, method="a"), Scored("b", 0.0, method="b"))
    whole = run_challenge(challenge, seeds=[0, 1], root=tmp_path)
    run_dir = tmp_path / "tiny"
    for path in (run_dir / "models").glob("seed_*/*"):  # gone, as on a fresh clone: summary.json records them
        for file in path.iterdir():
            file.unlink()
        path.rmdir()
    some = run_challenge(only_stages(challenge, ["a"]), seeds=[0], root=tmp_path)
    assert list(some["methods"]) == ["a"] and some["seeds"] == [0]
    assert set(some["stages"]) == set(whole["stages"])
    assert sorted(some["partial_runs"]) == ["seed_0/b", "seed_1/a", "seed_1/b"]
    assert some["partial_runs"]["seed_1/b"] == whole["methods"]["b"]["runs"][1]
    assert "other seeds (1) are kept in summary.json's partial_runs, out of this table: --seeds 0,1" in (
        capsys.readouterr().out
    )
    again = run_challenge(challenge, seeds=[0, 1], root=tmp_path)
    assert not list(run_dir.glob("models/seed_*/*"))  # nothing trained again
    assert again["methods"] == whole["methods"] and "partial_runs" not in again
    assert "partial_runs" not in capsys.readouterr().out


def test_runners_on_other_seeds_of_one_folder_keep_each_others_records(tmp_path: Path, importable: None) -> None:
    """
    Two runners on one folder, on other seeds (``--seeds 0`` beside ``--seeds 1``): the one that ends last keeps what
    the other recorded while it ran (it reads the record again before each write), so that a fresh clone trains
    neither seed again.
    """
    first = run_challenge(tiny(Scored("a", 0.0, method="a")), seeds=[0], root=tmp_path)
    run_dir = tmp_path / "tiny"
    (run_dir / "summary.json").rename(run_dir / "other.json")  # seed 0's record, written meanwhile below
    second = run_challenge(tiny(Meanwhile("a", 0.0, method="a")), seeds=[1], root=tmp_path)
    assert [run["seed"] for run in second["methods"]["a"]["runs"]] == [1]
    assert second["partial_runs"] == {"seed_0/a": first["methods"]["a"]["runs"][0]}
    assert set(second["stages"]) == {"seed_0/a", "seed_1/a"}
    shutil.rmtree(run_dir / "models")  # a fresh clone
    both = run_challenge(tiny(Scored("a", 0.0, method="a")), seeds=[0, 1], root=tmp_path)
    assert not (run_dir / "models").exists()  # nothing trained again
    assert both["methods"]["a"]["runs"] == [first["methods"]["a"]["runs"][0], second["methods"]["a"]["runs"][0]]
    assert sorted(path.name for path in run_dir.iterdir()) == ["other.json", "summary.json"]  # no temporary file left


def test_a_runner_waits_for_the_folders_lock_to_record(tmp_path: Path, importable: None) -> None:
    """
    While another runner holds the folder's lock (between its read of ``summary.json`` and its write), a runner whose
    stage has finished waits to record it, and records it once the lock is released.
    """
    run_dir = tmp_path / "tiny"
    run_dir.mkdir()
    finished: list[dict[str, Any]] = []
    with record_lock(run_dir):
        runner = threading.Thread(
            target=lambda: finished.append(run_challenge(tiny(Scored("a", 0.0, method="a")), seeds=[0], root=tmp_path))
        )
        runner.start()
        marker = run_dir / "models" / "seed_0" / "a" / STAGE_MARKER
        deadline = time.monotonic() + 60
        while not marker.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert marker.exists(), "the stage did not finish"
        runner.join(timeout=1.0)
        assert runner.is_alive() and not (run_dir / "summary.json").exists()  # waiting for the lock
    runner.join(timeout=60)
    assert not runner.is_alive() and [run["seed"] for run in finished[0]["methods"]["a"]["runs"]] == [0]
    assert json.loads((run_dir / "summary.json").read_text())["methods"] == finished[0]["methods"]


def test_a_dry_run_shows_what_would_run_and_runs_nothing(
    tmp_path: Path, importable: None, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--dry-run`` lists the finished stages and those to run, writes nothing, and a later run does what it said."""
    challenge = tiny(Sleep("source", 0.0), Sleep("target", 0.0, needs=("source",)))
    monkeypatch.setitem(CHALLENGES, "tiny", challenge)
    challenges_main(["tiny", "--root", str(tmp_path), "--dry-run"])
    assert not (tmp_path / "tiny").exists()
    out = capsys.readouterr().out
    assert out.startswith("tiny (smoke budget, seeds [0]): 2 stages to run, 0 finished\n")
    assert "  run   seed 0 source: sleep 0.0 s\n  run   seed 0 target: sleep 0.0 s" in out
    run_challenge(challenge, seeds=[0], root=tmp_path)
    capsys.readouterr()
    plan = run_challenge(challenge, seeds=[0, 1], root=tmp_path, dry_run=True)
    assert plan == {"to_run": ["seed_1/source", "seed_1/target"], "finished": ["seed_0/source", "seed_0/target"]}
    out = capsys.readouterr().out
    assert "  done  seed 0 source (" in out and "  run   seed 1 target: sleep 0.0 s" in out
    assert not (tmp_path / "tiny" / "models" / "seed_1").exists()
    challenges_main(["tiny", "--root", str(tmp_path), "--seeds", "1-2", "--dry-run"])  # named seeds, not a count
    out = capsys.readouterr().out
    assert out.startswith("tiny (smoke budget, seeds [1, 2]): 4 stages to run, 0 finished\n") and "seed 0" not in out
