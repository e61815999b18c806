r"""What a sweep shows while it runs: a bar on a terminal, a line per finished run elsewhere.

On a TTY one line is redrawn in place (``\r``) at most ten times per wall second,
as a single run's progress is::

    [#######-------------] 14/40 runs | 1 failed | 2 running | 2 workers | 0:21 left

and a run that did not complete is printed above it, on a line of its own.
Elsewhere (a pipe, a file, CI) each finished run is one plain line::

    [14/40] strategy.name=time seed 7: completed, makespan 28.1 s (wall 1.02 s)

The counts take in the runs of a resumed sweep (``resuming: 12 of 40 runs done
in runs/sweep-x/, 28 to run`` says so first); the time left is the runs left at
the pace of the runs finished since this sweep (re)started. The last line sums up
the sweep (:func:`last_line`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Final, TextIO, final

from ..output._results import RunStatus
from ._files import format_number
from ._outcome import SweepOutcome, SweepRun
from ._plan import SweepPlan

__all__ = ["SweepDisplay", "last_line"]

_TTY_PERIOD: Final = 0.1
"""Wall seconds between redraws on a TTY."""
_BAR_WIDTH: Final = 20


@final
class SweepDisplay:
    """Shows how far a sweep is on ``stream``, throttled by wall time on a TTY.

    Args:
        stream: where to write (e.g. ``sys.stderr``).
        plan: the sweep.
        tty: redraw a bar in place; ``None`` asks ``stream.isatty()``.
        now: the wall clock, in seconds.
    """

    def __init__(
        self,
        stream: TextIO,
        plan: SweepPlan,
        *,
        tty: bool | None = None,
        now: Callable[[], float] = time.monotonic,
    ) -> None:
        self._stream = stream
        self._plan = plan
        self._tty = stream.isatty() if tty is None else tty
        self._now = now
        self._started = now()
        self._due = -math.inf
        self._done = 0
        self._here = 0  # finished since this sweep (re)started: the pace
        self._failed = 0
        self._timed_out = 0
        self._running = 0
        self._workers: int | None = None
        self._shown_width = 0

    def resumed(self, runs: Sequence[SweepRun], out: Path) -> None:
        """Counts the runs a resumed sweep found done in ``out``, and says so."""
        for run in runs:
            self._count(run)
        done, total = self._done, self._plan.runs
        self._line(f"resuming: {done} of {total} runs done in {out}/, {total - done} to run")

    def note(self, text: str) -> None:
        """Prints ``text`` on a line of its own."""
        self._line(text)

    def finished(self, run: SweepRun, running: int, workers: int | None) -> None:
        """Counts ``run``, finished now; ``running`` runs and ``workers`` workers are left."""
        self._count(run)
        self._here += 1
        self._running, self._workers = running, workers
        if not self._tty:
            self._write(f"[{self._done}/{self._plan.runs}] {describe(self._plan, run)}\n")
            return
        if not run.completed:
            self._line(describe(self._plan, run))
        self._due = -math.inf
        self.update(running, workers)

    def update(self, running: int, workers: int | None) -> None:
        """Redraws the bar (on a TTY) if it is due: the time left changes by itself."""
        self._running, self._workers = running, workers
        if not self._tty:
            return
        now = self._now()
        if now < self._due:
            return
        self._due = now + _TTY_PERIOD
        line = self.bar()
        padding = " " * max(0, self._shown_width - len(line))  # blanks a longer old line
        self._write(f"\r{line}{padding}")
        self._shown_width = len(line)

    def close(self, outcome: SweepOutcome) -> None:
        """Ends the bar and prints the last line."""
        self._line(last_line(outcome))

    def bar(self) -> str:
        """``[#######-------------] 14/40 runs | 1 failed | 2 running | 0:21 left``."""
        total = self._plan.runs
        filled = min(_BAR_WIDTH, self._done * _BAR_WIDTH // total) if total else _BAR_WIDTH
        parts = [
            f"[{'#' * filled}{'-' * (_BAR_WIDTH - filled)}] {self._done}/{total} runs",
            f"{self._failed} failed",
        ]
        if self._timed_out:
            parts.append(f"{self._timed_out} timed out")
        parts.append(f"{self._running} running")
        if self._workers is not None:
            parts.append(f"{self._workers} worker{'s' if self._workers != 1 else ''}")
        parts.append(f"{self._left()} left")
        return " | ".join(parts)

    def _left(self) -> str:
        left = self._plan.runs - self._done
        if not left:
            return "0:00"
        if not self._here:
            return "-:--"
        seconds = round(left * (self._now() - self._started) / self._here)
        hours, rest = divmod(seconds, 3600)
        clock = f"{rest // 60:02d}:{rest % 60:02d}" if hours else f"{rest // 60}:{rest % 60:02d}"
        return f"{hours}:{clock}" if hours else clock

    def _count(self, run: SweepRun) -> None:
        self._done += 1
        self._failed += run.status is RunStatus.FAILED
        self._timed_out += run.status is RunStatus.TIMED_OUT

    def _line(self, text: str) -> None:
        """``text`` on a line of its own; on a TTY, above the bar (drawn again next time)."""
        if self._tty and self._shown_width:
            self._write(f"\r{' ' * self._shown_width}\r")
            self._shown_width = 0
            self._due = -math.inf
        self._write(text + "\n")

    def _write(self, text: str) -> None:
        self._stream.write(text)
        self._stream.flush()


def describe(plan: SweepPlan, done: SweepRun) -> str:
    """``strategy.name=time seed 3: completed, makespan 28.1 s (wall 0.3 s)``."""
    where = plan.describe(done.point)
    name = f"{where} seed {done.seed}" if where else f"seed {done.seed}"
    figures = done.scalars
    if done.completed:
        what = "completed"
        if "makespan" in figures:
            what += f", makespan {format_number(figures['makespan'])} s"
    elif done.status is RunStatus.FAILED:
        what = f"failed: {(done.error or 'no error given').splitlines()[0]}"
    else:
        what = str(done.status)
        if "sim_time" in figures:
            what += f" at {format_number(figures['sim_time'])} s"
    wall = f" (wall {figures['wall_time']:.2f} s)" if "wall_time" in figures else ""
    return f"{name}: {what}{wall}"


def last_line(outcome: SweepOutcome) -> str:
    """``sweep: 40 runs (37 completed, 2 failed, 1 timed out) in 41.2 s wall, 2 worker processes``.

    With, where they apply, the runs resumed and the workers lost
    (``(40 completed; 12 resumed; 1 worker lost, 2 runs sent again)``).
    """
    plan = outcome.plan
    done = len(outcome.runs)
    ran = f"interrupted after {done} of {plan.runs} runs" if outcome.interrupted else f"{done} runs"
    statuses = [run.status for run in outcome.runs]
    counts = [f"{statuses.count(RunStatus.COMPLETED)} completed"]
    counts += [
        f"{count} {name}"
        for status, name in (
            (RunStatus.FAILED, "failed"),
            (RunStatus.STOPPED, "stopped"),
            (RunStatus.TIMED_OUT, "timed out"),
        )
        if (count := statuses.count(status))
    ]
    extras = [", ".join(counts)]
    if outcome.resumed:
        extras.append(f"{outcome.resumed} resumed")
    if outcome.workers_lost:
        lost = f"{outcome.workers_lost} worker{'s' if outcome.workers_lost != 1 else ''} lost"
        again = f"{outcome.runs_resent} run{'s' if outcome.runs_resent != 1 else ''} sent again"
        extras.append(f"{lost}, {again}")
    where = outcome.ran_on or f"{outcome.jobs} worker process{'es' if outcome.jobs != 1 else ''}"
    if outcome.resumed == done and not outcome.interrupted:
        where = "nothing left to run"
    return f"sweep: {ran} ({'; '.join(extras)}) in {outcome.wall_time:.1f} s wall, {where}"
