"""
What the challenge runner shows while it runs. On a terminal, a live table (``rich``) of the running stages: each
one's key (seed and stage), what it does, its env steps done out of its total (read from the ``progress.csv`` it
writes as it trains), the time it has run and an estimate of the time left; above it, the stages done out of all
of them, and one line per stage started or finished. Elsewhere (a log file, CI), the same lines, plain, with a line
of env steps every few minutes for a long stage.
"""

from __future__ import annotations

import csv
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType

from rich import box
from rich.console import Console
from rich.live import Live
from rich.progress_bar import ProgressBar
from rich.table import Table
from rich.text import Text

from sb3_pilot.experiments.challenges.backends import StageFailed
from sb3_pilot.experiments.challenges.stages import PROGRESS_CSV

#: The column of SB3's ``progress.csv`` that holds the env steps done.
STEPS_COLUMN = "time/total_timesteps"
#: Plain lines: seconds between two lines of a running stage's env steps.
PLAIN_EVERY_S = 300.0
#: Live display: seconds between two redraws, and between two reads of a stage's ``progress.csv``.
REFRESH_S = 0.5
READ_EVERY_S = 2.0
#: Bytes read from the end of ``progress.csv`` to find its last row.
TAIL_BYTES = 16_384


def steps_done(stage_dir: Path) -> tuple[float, int] | None:
    """
    The env steps a zoo stage has done, from the last row of the ``progress.csv`` its logger writes (header and tail
    only: cheap however long the file).

    :param stage_dir: the stage's folder
    :return: when that row was written (the file's modification time) and its env steps; None before the first row
    """
    path = stage_dir / PROGRESS_CSV
    try:
        with path.open("rb") as file:
            header = next(csv.reader([file.readline().decode(errors="replace")]), [])
            modified, size = os.fstat(file.fileno()).st_mtime, os.fstat(file.fileno()).st_size
            file.seek(max(size - TAIL_BYTES, file.tell()))
            tail = file.read().decode(errors="replace")
    except OSError:
        return None
    complete = tail[: tail.rfind("\n")]  # the logger may be writing the last line
    if STEPS_COLUMN not in header or not complete.strip():
        return None
    row = next(csv.reader([complete[complete.rfind("\n") + 1 :]]), [])
    try:
        return modified, int(float(row[header.index(STEPS_COLUMN)]))
    except (IndexError, ValueError):  # an empty cell, or SB3 rewriting the file for a new column
        return None


def clock(seconds: float | None) -> str:
    """``h:mm:ss`` (``-`` for None)."""
    if seconds is None:
        return "-"
    minutes, secs = divmod(round(seconds), 60)
    return f"{minutes // 60}:{minutes % 60:02d}:{secs:02d}"


def stage_name(key: str) -> str:
    """``seed 0 her`` for the key ``seed_0/her``."""
    return key.replace("seed_", "seed ", 1).replace("/", " ", 1)


@dataclass
class StageProgress:
    """
    A running stage as the display sees it.

    :param key: ``seed_<k>/<stage>``
    :param description: what it does (one short line)
    :param stage_dir: its folder, where its ``progress.csv`` grows
    :param total: the env steps it trains for (None: a stage that does not train)
    :param start: when it started (``time.time()``)
    :param first: when the first row with env steps was written, and its env steps
    :param last: the same for the latest row read
    """

    key: str
    description: str
    stage_dir: Path
    total: int | None
    start: float
    first: tuple[float, int] | None = None
    last: tuple[float, int] | None = None
    read_at: float = field(default=float("-inf"), repr=False)
    reported_at: float = field(default=float("-inf"), repr=False)

    @property
    def steps(self) -> int | None:
        """Env steps done (None: none read yet)."""
        return None if self.last is None else self.last[1]

    def read(self, now: float, every: float = READ_EVERY_S) -> None:
        """Read its env steps, unless it was read less than ``every`` seconds ago or it does not train."""
        if self.total is None or now - self.read_at < every:
            return
        self.read_at = now
        reading = steps_done(self.stage_dir)
        if reading is not None:
            self.first = self.first or reading
            self.last = reading

    def eta(self, now: float) -> float | None:
        """
        Seconds left: its env steps still to do at the pace between the first and the latest row read (at the pace
        since it started while only one was read); None before any, or for a stage that does not train.
        """
        if self.total is None or self.first is None or self.last is None:
            return None
        (first_time, first_steps), (last_time, last_steps) = self.first, self.last
        if last_steps >= self.total:
            return 0.0
        if last_steps > first_steps and last_time > first_time:
            rate = (last_steps - first_steps) / (last_time - first_time)
        elif last_steps > 0 and last_time > self.start:
            rate = last_steps / (last_time - self.start)
        else:
            return None
        return max((self.total - last_steps) / rate - (now - last_time), 0.0)

    def line(self, now: float) -> str:
        """Its env steps, time run and time left, in words."""
        elapsed = f"{clock(now - self.start)} elapsed"
        if self.total is None:
            return elapsed
        steps = self.steps or 0
        return f"{steps}/{self.total} env steps ({100 * steps / self.total:.0f}%), {elapsed}, ETA {clock(self.eta(now))}"


def render(title: str, done: int, total: int, elapsed: float, stages: Sequence[StageProgress], now: float) -> Table:
    """
    The live display: the stages done out of all, then a row per running stage (key, what, env steps with a bar,
    elapsed, ETA).

    :param title: the run (challenge and budget)
    :param done: stages finished (skipped ones included)
    :param total: all the run's stages
    :param elapsed: seconds since the run started
    :param stages: the running stages
    :param now: the time (``time.time()``)
    """
    table = Table(
        title=f"{title}: {done}/{total} stages done, {clock(elapsed)}",
        title_justify="left",
        box=box.SIMPLE_HEAD,
        expand=False,
    )
    for column in ("stage", "what", "env steps", ""):
        table.add_column(column, overflow="fold")
    table.add_column("elapsed", justify="right")
    table.add_column("ETA", justify="right")
    for stage in stages:
        if stage.total is None:
            steps, bar = "-", Text("")
        else:
            steps = f"{stage.steps or 0}/{stage.total}"
            bar = ProgressBar(total=stage.total, completed=min(stage.steps or 0, stage.total), width=20)
        table.add_row(stage.key, stage.description, steps, bar, clock(now - stage.start), clock(stage.eta(now)))
    return table


class RunDisplay:
    """
    The runner's output: a line per event, each led by ``[title done/total elapsed]``; with ``live``, under them a live
    table of the running stages (:func:`render`), otherwise a ``running:`` line after each start or end and, every
    ``plain_every`` seconds, a line of each running stage's env steps. Use it as a context manager.

    :param title: the run (challenge and budget)
    :param total: all the run's stages
    :param done: stages finished before it starts (skipped)
    :param live: the live table (on a terminal); plain lines otherwise
    :param console: where it writes (None: stdout)
    :param plain_every: plain lines: seconds between two lines of a running stage's env steps
    """

    def __init__(
        self,
        title: str,
        total: int,
        done: int = 0,
        live: bool = False,
        console: Console | None = None,
        plain_every: float = PLAIN_EVERY_S,
    ) -> None:
        self.title, self.total, self.done, self.plain_every = title, total, done, plain_every
        self.running: dict[str, StageProgress] = {}
        self.start = time.time()
        self.console = console or Console(file=sys.stdout, highlight=False)
        self._live = None
        if live:
            self._live = Live(console=self.console, auto_refresh=False, transient=True, get_renderable=self._table)
        self._drawn_at = float("-inf")

    def __enter__(self) -> RunDisplay:
        if self._live is not None:
            self._live.start()
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None, traceback: TracebackType | None) -> None:
        if self._live is not None:
            self._live.stop()

    def label(self) -> str:
        return f"[{self.title} {self.done}/{self.total} {time.time() - self.start:.0f}s]"

    def print(self, text: str) -> None:
        """A line, led by :meth:`label` (above the live table)."""
        line = f"{self.label()} {text}"
        if self._live is None:
            print(line, flush=True)
            return
        if self._live.is_started:  # the table below the line as it is now, not as it was last drawn
            self._live.refresh()
        self.console.print(Text(line))

    def skipped(self, text: str) -> None:
        """A stage finished before: one more done."""
        self.done += 1
        self.print(text)

    def started(self, key: str, description: str, stage_dir: Path, total: int | None) -> None:
        """
        A stage started.

        :param key: ``seed_<k>/<stage>``
        :param description: what it does (one short line)
        :param stage_dir: its folder
        :param total: the env steps it trains for (None: it does not train)
        """
        now = time.time()
        self.running[key] = StageProgress(key, description, stage_dir, total, now, reported_at=now)
        self.print(f"{stage_name(key)}: {description}")
        self._show_running()

    def finished(self, key: str, wall_time_s: float) -> None:
        """A stage finished, in ``wall_time_s`` seconds."""
        self.running.pop(key, None)
        self.done += 1
        self.print(f"{stage_name(key)}: finished in {wall_time_s:.0f} s")
        if self.running:
            self._show_running()

    def failed(self, error: StageFailed, running: list[str]) -> None:
        """
        A stage failed (its log's tail comes with the run's error, at the end).

        :param error: its error
        :param running: the stages still running, which finish before the run ends
        """
        self.running.pop(error.key, None)
        waiting = f"; waiting for {', '.join(running)} to finish (Ctrl-C stops them)" if running else ""
        self.print(f"{stage_name(error.key)}: failed ({error.reason}), log: {error.log}{waiting}")
        if self.running:
            self._show_running()

    def tick(self) -> None:
        """Called while stages run: redraw the live table, or print the env steps of a stage not reported for long."""
        now = time.time()
        if self._live is not None:
            if now - self._drawn_at >= REFRESH_S:
                self._drawn_at = now
                self._live.refresh()
            return
        for stage in self.running.values():
            if now - stage.reported_at >= self.plain_every:
                stage.reported_at = now
                stage.read(now, every=0.0)
                self.print(f"{stage_name(stage.key)}: {stage.line(now)}")

    def _show_running(self) -> None:
        if self._live is None:
            print(f"{self.label()[:-1]} running: {', '.join(self.running) or '-'}]", flush=True)

    def _table(self) -> Table:
        now = time.time()
        for stage in self.running.values():
            stage.read(now)
        return render(self.title, self.done, self.total, now - self.start, list(self.running.values()), now)
