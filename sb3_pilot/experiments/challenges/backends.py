"""
Execution backends of the challenge runner: the stages of a challenge as a graph (per seed, each stage depends on
the stages it reads from), run by up to ``jobs`` processes on this machine or as Ray tasks.

Every stage runs in a process of its own, forked from a server that has imported this package, torch, SB3 and the zoo
once (:mod:`multiprocessing`'s fork server; where there is none, a fresh interpreter): its stdout and stderr go to
``stage.log`` in its folder (a zoo stage's command line to ``command.txt`` too), it uses ``ctx.threads`` torch /
OpenMP threads (1 unless told otherwise, so that N stages on N cores do not fight), it writes its marker when it
succeeds and dies with the process that started it. It starts in a fresh folder, but a zoo stage that continues from
its checkpoint (``resume_from``: the zoo's ``--resume``), which keeps its folder. After a failed stage no other starts
(``keep_going``: none that reads from a failed stage), the stages running finish and are recorded, then
:class:`StageFailed` (its key and its log's tail) is raised; an interrupt (Ctrl-C, SIGTERM) stops the running stages.

- ``local`` (``--jobs N``): a dependency-aware submit loop over the stage processes, at most N at once.
- ``ray`` (``--backend ray [--ray-address ADDR]``): every stage a Ray task declaring ``ctx.threads`` CPUs, its
  dependencies passed as object references (the markers of the stages it reads from). The results folder must be
  on storage every node sees (stages read each other's models and replay buffers through their paths).
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import multiprocessing.connection
import multiprocessing.forkserver
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cloudpickle

from sb3_pilot.experiments.challenges.stages import (
    STAGE_COMMAND,
    STAGE_LOG,
    STAGE_MARKER,
    STAGE_STARTED,
    Stage,
    StageContext,
    ZooTrain,
)

#: The backends of :func:`~sb3_pilot.experiments.challenges.run_challenge`.
BACKENDS = ("local", "ray")
#: Lines of a failed stage's log quoted in its error.
TAIL_LINES = 30
#: Seconds between two looks at the running stages.
POLL_S = 0.2
#: Seconds a stopped stage gets to end after SIGTERM, before SIGKILL.
STOP_GRACE_S = 10.0
#: Ray's setting of its workers' niceness (a local cluster started here: 0).
WORKER_NICENESS = "RAY_worker_niceness"
#: What the fork server of the stage processes imports once, before it forks them: this package with torch, SB3 and
#: the zoo (about 4 s), and ``torch._dynamo``, which torch imports when a stage builds its first optimizer (2-3 s).
PRELOAD = ("sb3_pilot.experiments.challenges.backends", "torch._dynamo")
#: Environment variables of the thread pools; a stage gets ``ctx.threads``, the fork server 1 (its BLAS pool's size
#: is read once, when numpy loads: a stage's numpy keeps one thread).
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


class StageFailed(RuntimeError):
    """
    A stage failed: the message names it, says why and quotes the tail of its log.

    :param key: ``seed_<k>/<stage>``
    :param reason: why (exit status, node, the other stages that failed or did not run)
    :param log: its log file
    :param tail: the last lines of its log
    """

    def __init__(self, key: str, reason: str, log: str, tail: str) -> None:
        super().__init__(key, reason, log, tail)
        self.key, self.reason, self.log, self.tail = key, reason, log, tail

    def __str__(self) -> str:
        return f"Stage {self.key} failed ({self.reason}). Last lines of {self.log}:\n{self.tail}"


@dataclass
class StageTask:
    """
    One stage of one seed to run, with all its process needs (sent to it with ``cloudpickle``).

    :param key: ``seed_<k>/<stage>``
    :param stage: the stage
    :param ctx: its context (``ctx.outputs``: the output of every stage of the seed)
    :param stage_dir: its folder
    :param config: its configuration as stored (:func:`~sb3_pilot.experiments.challenges.stages.portable`)
    :param digest: the hash of its configuration and of the stages it reads from
    :param needs: keys of the stages it reads from
    :param resume_from: the env steps of the checkpoint in its folder that a zoo stage continues from (None: it starts
        over in a fresh folder)
    """

    key: str
    stage: Stage
    ctx: StageContext
    stage_dir: Path
    config: dict[str, Any]
    digest: str
    needs: tuple[str, ...]
    resume_from: int | None = None

    @property
    def log(self) -> Path:
        """The stage process's output."""
        return self.stage_dir / STAGE_LOG


#: Called when a stage starts, when it finishes (with its marker), at every look at the running stages, and when a
#: stage fails (with its error and the keys of the stages still running).
OnStart = Callable[[StageTask], None]
OnFinish = Callable[[StageTask, dict[str, Any]], None]
OnTick = Callable[[], None]
OnFail = Callable[[StageFailed, list[str]], None]


def _nothing(*args: Any) -> None:
    """The default :data:`OnTick` and :data:`OnFail`."""


def log_tail(path: Path, lines: int = TAIL_LINES) -> str:
    """The last non-empty ``lines`` lines of a log (progress bars' carriage returns count as line ends)."""
    if not path.exists():
        return f"(no log: {path} does not exist)"
    with path.open("rb") as file:
        file.seek(max(path.stat().st_size - 50_000, 0))
        text = file.read().decode(errors="replace")
    return "\n".join([line for line in re.split(r"[\r\n]+", text) if line.strip()][-lines:])


def failure(task: StageTask, reason: str) -> StageFailed:
    """The error of a failed stage: its key, why, and its log's tail."""
    return StageFailed(task.key, reason, str(task.log), log_tail(task.log))


def run_failed(failures: Sequence[StageFailed], not_run: Sequence[str]) -> StageFailed:
    """
    The error a run with failed stages ends with: the first failure, naming the other failed stages and those not run.

    :param failures: the failed stages' errors, in the order they failed
    :param not_run: the stages that did not start because of them
    """
    first, notes = failures[0], [failures[0].reason]
    if len(failures) > 1:
        notes.append(f"also failed: {', '.join(error.key for error in failures[1:])}")
    if not_run:
        notes.append(f"not run: {', '.join(not_run)}")
    return StageFailed(first.key, "; ".join(notes), first.log, first.tail)


def read_marker(task: StageTask) -> dict[str, Any]:
    """The marker the stage's process wrote when it finished."""
    return json.loads((task.stage_dir / STAGE_MARKER).read_text())


class StageProcess:
    """
    A stage's process (:mod:`multiprocessing`), with the part of :class:`subprocess.Popen`'s interface the runners use.

    :param process: the started process
    """

    def __init__(self, process: multiprocessing.process.BaseProcess) -> None:
        self.process = process

    def poll(self) -> int | None:
        """Its exit status (minus the signal that killed it), None while it runs."""
        return self.process.exitcode

    def terminate(self) -> None:
        self.process.terminate()

    def kill(self) -> None:
        self.process.kill()

    def wait(self, timeout: float | None = None) -> int:
        """
        Wait for it to end.

        :raise subprocess.TimeoutExpired: when it still runs after ``timeout`` seconds
        """
        self.process.join(timeout)
        if self.process.exitcode is None:
            raise subprocess.TimeoutExpired(f"stage process {self.process.pid}", timeout or 0.0)
        return self.process.exitcode


@contextlib.contextmanager
def _environment(values: dict[str, str]) -> Iterator[None]:
    """Set environment variables for the block's duration."""
    saved = {name: os.environ.get(name) for name in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _context() -> multiprocessing.context.BaseContext:
    """
    The stage processes' start method: forked from the fork server (started once, with :data:`PRELOAD` imported and
    one thread per pool), or where there is none a fresh interpreter.
    """
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    multiprocessing.set_forkserver_preload(list(PRELOAD))
    with _environment(dict.fromkeys(THREAD_VARIABLES, "1")):
        multiprocessing.forkserver.ensure_running()
    return multiprocessing.get_context("forkserver")


#: This process's pipe for its stages (:func:`_runner_pipe`): its pid, the read end and the write end.
_RUNNER_PIPE: tuple[int, multiprocessing.connection.Connection, multiprocessing.connection.Connection] | None = None


def _runner_pipe() -> multiprocessing.connection.Connection:
    """
    The read end of a pipe that this process (a runner) keeps open and never writes to: each stage process it starts
    gets it, and ends when it reads the pipe's end (:func:`_die_with_runner`), so that no stage outlives its runner.
    """
    global _RUNNER_PIPE
    if _RUNNER_PIPE is None or _RUNNER_PIPE[0] != os.getpid():  # a forked copy of a runner makes its own
        _RUNNER_PIPE = (os.getpid(), *multiprocessing.Pipe(duplex=False))
    return _RUNNER_PIPE[1]


def start_stage(task: StageTask) -> StageProcess:
    """
    Start a stage's process in a fresh folder (but a stage that resumes: in its own), its output to ``stage.log``, with
    this process's working folder and environment and ``ctx.threads`` threads.

    :return: the process (it exits with 0 once the stage's marker is written)
    """
    if task.stage_dir.exists() and task.resume_from is None:  # interrupted, or configured differently: start over
        shutil.rmtree(task.stage_dir)
    task.stage_dir.mkdir(parents=True, exist_ok=True)
    task.log.write_bytes(b"")
    threads = str(task.ctx.threads)
    env = {**os.environ, **dict.fromkeys(THREAD_VARIABLES, threads)}
    args = (cloudpickle.dumps(task), os.getcwd(), env, _runner_pipe())
    process = _context().Process(target=stage_process_main, args=args, name=task.key, daemon=False)
    process.start()
    return StageProcess(process)


@contextlib.contextmanager
def _interrupt_deferred() -> Iterator[None]:
    """
    Ctrl-C (SIGINT) while the block runs acts once it is over, as it would have then (the main thread's handler,
    ``KeyboardInterrupt`` by default): a stage process started in the block is registered before the runner stops.
    Where Ctrl-C came in between, the stage was a child not yet registered, and the interpreter's exit waited for it
    to end (``multiprocessing`` joins its children), for as long as the stage ran.
    """
    if threading.current_thread() is not threading.main_thread():  # only the main thread takes signals
        yield
        return
    received: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if received and callable(previous):
            previous(signal.SIGINT, None)
        elif received and previous == signal.SIG_DFL:  # the signal's default action, now
            os.kill(os.getpid(), signal.SIGINT)


def stop_stages(processes: Sequence[StageProcess]) -> None:
    """Stop stage processes: SIGTERM, then SIGKILL after :data:`STOP_GRACE_S`; they are reaped, none is left."""
    for process in processes:
        if process.poll() is None:
            process.terminate()
    deadline = time.monotonic() + STOP_GRACE_S
    for process in processes:
        try:
            process.wait(max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def _die_with_runner(runner: multiprocessing.connection.Connection) -> None:
    """
    End this process (SIGKILL) once its runner has ended, however it ended: a thread waits on a pipe that the runner
    never writes to and only the runner holds open, whose end it sees when the runner's process is gone. (Neither the
    fork server, which lives while its children do, nor a parent-death signal, which would follow the fork server,
    tells.)

    :param runner: the pipe's read end (:func:`_runner_pipe`)
    """

    def watch() -> None:
        with contextlib.suppress(EOFError, OSError):
            runner.recv_bytes()
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="die-with-runner", daemon=True).start()


def stage_process_main(
    task_bytes: bytes, cwd: str, env: dict[str, str], runner: multiprocessing.connection.Connection
) -> None:
    """
    The process of one stage: it ends with its runner and leaves Ctrl-C (SIGINT) to it; its output to its log, the
    runner's working folder and environment; then it runs the stage and writes its marker, whose ``wall_time_s`` is
    the stage's time. A stage resumed from a checkpoint (``resumed_from``, its env steps) adds to this sitting's time
    the wall time its training took to reach the checkpoint in the earlier sittings (``earlier_sittings_s``, the
    checkpoint's ``training_s``; what an earlier sitting trained past its last checkpoint is not counted); where the
    checkpoint does not record it, its time is this sitting's.

    :param task_bytes: the :class:`StageTask`, pickled with ``cloudpickle``
    :param cwd: the runner's working folder
    :param env: the stage's environment variables
    :param runner: the read end of the runner's pipe (:func:`_runner_pipe`)
    """
    # Ctrl-C at a terminal reaches the stage too; the zoo's training would end normally on it (saving the model) and
    # the stage be recorded as finished after part of its steps: the runner, which stops its stages, takes it alone
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_runner(runner)
    task: StageTask = cloudpickle.loads(task_bytes)
    log = os.open(task.log, os.O_WRONLY | os.O_APPEND)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(log, 1)
    os.dup2(log, 2)
    os.close(log)
    os.chdir(cwd)
    os.environ.clear()
    os.environ.update(env)
    import torch as th

    th.set_num_threads(task.ctx.threads)
    print(f"[{task.key}] {task.stage.describe(task.ctx, task.stage_dir)}", flush=True)
    if isinstance(task.stage, ZooTrain):
        command = task.stage.command(task.ctx, task.stage_dir, resume=task.resume_from is not None)
        (task.stage_dir / STAGE_COMMAND).write_text(command + "\n")
        print(command, flush=True)
        if task.stage.checkpoint_freq:  # the configuration its checkpoints belong to
            (task.stage_dir / STAGE_STARTED).write_text(json.dumps({"config_hash": task.digest}) + "\n")
    earlier_s = None  # a resumed stage: the earlier sittings' training time to its checkpoint, where recorded
    if isinstance(task.stage, ZooTrain) and task.resume_from is not None:
        earlier_s = (task.stage.checkpoint(task.stage_dir) or {}).get("training_s")
    start = time.perf_counter()
    if isinstance(task.stage, ZooTrain):
        task.stage.run(task.ctx, task.stage_dir, resume=task.resume_from is not None)
    else:
        task.stage.run(task.ctx, task.stage_dir)
    marker = {"config_hash": task.digest, "config": task.config, "wall_time_s": time.perf_counter() - start}
    if task.resume_from is not None:
        marker["resumed_from"] = task.resume_from
        if earlier_s is not None:
            marker["wall_time_s"] += earlier_s
            marker["earlier_sittings_s"] = earlier_s
    (task.stage_dir / STAGE_MARKER).write_text(json.dumps(marker, indent=2, default=str))


def run_local(
    tasks: Sequence[StageTask],
    jobs: int,
    on_start: OnStart,
    on_finish: OnFinish,
    on_tick: OnTick = _nothing,
    on_fail: OnFail = _nothing,
    keep_going: bool = False,
) -> None:
    """
    Run stages on this machine, at most ``jobs`` at once, each once the stages it reads from have finished. After a
    stage fails, the stages running finish; no other starts, or with ``keep_going`` those that read from no failed
    stage do (other seeds', baselines).

    :param tasks: the stages to run, a stage after those it reads from (the others have finished before)
    :param jobs: how many stages may run at once
    :param on_start: called when a stage starts
    :param on_finish: called when a stage finishes
    :param on_tick: called every :data:`POLL_S` while stages run
    :param on_fail: called when a stage fails
    :param keep_going: after a failure, go on with the stages that do not read from a failed stage
    :raise StageFailed: once the stages running have finished, when a stage failed (:func:`run_failed`)
    """
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, not {jobs}")
    pending = list(tasks)
    to_run = {task.key for task in tasks}
    finished: set[str] = set()
    failures: list[StageFailed] = []
    not_run: list[str] = []
    running: dict[str, tuple[StageTask, StageProcess]] = {}
    try:
        while pending or running:
            blocked = {error.key for error in failures}
            for task in list(pending):  # a stage after those it reads from: what reads from a blocked one is blocked
                if failures and (not keep_going or blocked.intersection(task.needs)):
                    pending.remove(task)
                    not_run.append(task.key)
                    blocked.add(task.key)
            for task in list(pending):
                if len(running) >= jobs:
                    break
                if all(need in finished or need not in to_run for need in task.needs):
                    pending.remove(task)
                    with _interrupt_deferred():  # a stage started is a stage stopped: registered before Ctrl-C acts
                        running[task.key] = (task, start_stage(task))
                    on_start(task)
            if not running:
                if pending:
                    raise ValueError(f"Stages wait for stages that never run: {[task.key for task in pending]}")
                break
            time.sleep(POLL_S)
            on_tick()
            for key, (task, process) in list(running.items()):
                code = process.poll()
                if code is None:
                    continue
                del running[key]
                if code != 0:
                    failures.append(failure(task, f"exit status {code}"))
                    on_fail(failures[-1], list(running))
                    continue
                finished.add(key)
                on_finish(task, read_marker(task))
    finally:  # an error here or an interrupt (Ctrl-C): no stage process is left behind
        stop_stages([process for _, process in running.values()])
    if failures:
        raise run_failed(failures, not_run)


def _ray_stage(task: StageTask, *needs: dict[str, Any]) -> dict[str, Any]:
    """
    A Ray task: run a stage's process on this node and wait for it. Ray passes the markers of the stages it
    reads from as ``needs`` (it starts the task once they exist); cancelling the task stops the process.

    :return: the stage's marker
    :raise StageFailed: also when the outputs of the stages it reads from are not on this node
    """
    missing = [need for need in task.needs if not task.ctx.outputs[need.split("/")[1]].exists()]
    if missing:
        tail = f"missing here: {[str(task.ctx.outputs[need.split('/')[1]]) for need in missing]}"
        where = socket.gethostname()
        reason = f"the outputs of {', '.join(missing)} are not on {where}: --root must be on storage every node sees"
        raise StageFailed(task.key, reason, "(not started)", tail)
    process = start_stage(task)
    try:
        while (code := process.poll()) is None:
            time.sleep(POLL_S)
    finally:
        stop_stages([process])
    if code != 0:
        raise failure(task, f"exit status {code} on {socket.gethostname()}")
    return read_marker(task)


def run_ray(
    tasks: Sequence[StageTask],
    address: str | None,
    on_start: OnStart,
    on_finish: OnFinish,
    on_tick: OnTick = _nothing,
    on_fail: OnFail = _nothing,
    keep_going: bool = False,
) -> None:
    """
    Run stages as Ray tasks: each declares ``ctx.threads`` CPUs and gets the stages it reads from as object
    references. Without ``address`` and without a running Ray, ``ray.init()`` starts a local cluster (this
    machine's cores) and shuts it down afterwards; an initialised Ray is used as it is. After a stage fails, the
    tasks not started yet are cancelled (``keep_going``: only those that read from a failed stage, which Ray does not
    start) and the running ones finish.

    :param tasks: the stages to run, a stage after those it reads from (the others have finished before)
    :param address: a Ray cluster's address (``ray.init(address=...)``), e.g. ``auto`` or ``ray://HEAD:10001``
    :param on_start: called when a stage is seen running (its ``stage.log`` exists)
    :param on_finish: called when a stage finishes
    :param on_tick: called about every second while stages run
    :param on_fail: called when a stage fails
    :param keep_going: after a failure, go on with the stages that do not read from a failed stage
    :raise StageFailed: once the running tasks have finished, when a stage failed (:func:`run_failed`)
    """
    try:
        import ray
    except ImportError as error:
        raise ImportError("--backend ray needs Ray: pip install 'sb3-pilot[ray]' (or pip install ray)") from error
    started_here = not ray.is_initialized()
    if started_here:
        local = {"include_dashboard": False} if address is None else {}
        # Ray runs its workers at nice +15 by default (RAY_worker_niceness); the stages are the work: they run at the
        # runner's priority, as with --jobs (a cluster's nodes keep what their `ray start` was given)
        previous = os.environ.get(WORKER_NICENESS)
        os.environ.setdefault(WORKER_NICENESS, "0")
        try:
            ray.init(address=address, log_to_driver=False, **local)
        finally:
            if previous is None:
                os.environ.pop(WORKER_NICENESS, None)
    remote = ray.remote(_ray_stage)
    refs: dict[str, Any] = {}
    for task in tasks:
        dependencies = [refs[need] for need in task.needs if need in refs]
        refs[task.key] = remote.options(name=task.key, num_cpus=task.ctx.threads).remote(task, *dependencies)
    by_ref = {ref: task for task, ref in zip(tasks, refs.values(), strict=True)}
    waiting, seen = list(refs.values()), set()
    failures: list[StageFailed] = []
    not_run: list[str] = []
    try:
        while waiting:
            done, waiting = ray.wait(waiting, num_returns=1, timeout=1.0)
            on_tick()
            for ref in waiting:  # a task has started once it has opened its log (the folder was cleared before)
                if by_ref[ref].key not in seen and by_ref[ref].log.exists():
                    seen.add(by_ref[ref].key)
                    on_start(by_ref[ref])
            for ref in done:
                task = by_ref[ref]
                try:
                    marker = ray.get(ref)
                except Exception as error:
                    cause = getattr(error, "cause", error)
                    if isinstance(cause, StageFailed) and cause.key != task.key:  # it reads from a failed stage
                        not_run.append(task.key)
                        continue
                    in_ray = f"{type(error).__name__} in Ray: {error}"
                    failed = cause if isinstance(cause, StageFailed) else failure(task, in_ray)
                    failures.append(failed)
                    if not keep_going:  # the tasks not started yet are cancelled, the running ones finish
                        cancelled = [other for other in waiting if by_ref[other].key not in seen]
                        for other in cancelled:
                            ray.cancel(other)
                        not_run.extend(by_ref[other].key for other in cancelled)
                        waiting = [other for other in waiting if by_ref[other].key in seen]
                    on_fail(failed, [by_ref[other].key for other in waiting])
                    continue
                if task.key not in seen:
                    seen.add(task.key)
                    on_start(task)
                on_finish(task, marker)
    finally:  # an interrupt: cancel the rest (a running task stops its process) and wait for them
        for ref in waiting:
            ray.cancel(ref)
        if waiting:
            ray.wait(waiting, num_returns=len(waiting), timeout=3 * STOP_GRACE_S)
        if started_here:
            ray.shutdown()
    if failures:
        raise run_failed(failures, not_run)
