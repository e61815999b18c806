"""``runs.csv``: a row per finished run, written as the runs finish, and read back to resume.

Columns: the varied keys, ``seed``, ``status``, ``error``, then every metric
(``repr`` of the float: read back exactly; empty where the run has none).

While a sweep runs, :class:`RunsFile` appends each finished run as one line,
with one ``write()`` on a file opened for appending: a reader, or a sweep killed
at any moment, sees whole rows (only a crash of the machine can tear the last
one, which :func:`read_runs` drops). A run that brings a metric the header lacks
(the first completed run after timed-out ones brings ``makespan``) rewrites the
whole file at once, with the grown header. The data reaches the disk at most a
second after its row (``fsync``); the file survives the sweep's process anyway.

At the end :func:`write_runs_csv` rewrites it in its final form: rows by point
then seed, metrics in the order first seen in that order. So it is the same
bytes whatever order the runs finished in and wherever they ran (but for the
wall times), and a resumed sweep's earlier rows come out as they were.
"""

from __future__ import annotations

import csv
import io
import os
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Final, final

from .._spec._config import ScenarioError
from ..output._atomic_files import atomic_text_file
from ..output._results import RunStatus
from ._outcome import SweepRun
from ._plan import SweepPlan

__all__ = ["RunsFile", "read_runs", "write_runs_csv"]

_FIXED: Final = ("seed", "status", "error")
_SYNC_PERIOD: Final = 1.0
"""Wall seconds between two ``fsync`` of the rows appended."""


def write_runs_csv(plan: SweepPlan, runs: Sequence[SweepRun], path: Path) -> None:
    """Writes ``runs`` (in that order) to ``path`` whole or not at all."""
    text = _text(plan, runs, _metrics(runs))
    with atomic_text_file(path) as stream:
        stream.write(text)


@final
class RunsFile:
    """``runs.csv`` while the sweep runs: rewritten now with ``runs``, then a line per run.

    Args:
        path: the file.
        plan: the sweep.
        runs: the rows it starts with (those of a resumed sweep).
        now: the wall clock, in seconds.
    """

    def __init__(
        self,
        path: Path,
        plan: SweepPlan,
        runs: Sequence[SweepRun] = (),
        now: Callable[[], float] = time.monotonic,
    ) -> None:
        self._path = path
        self._plan = plan
        self._runs = list(runs)
        self._metrics = _metrics(self._runs)
        self._now = now
        self._synced = now()
        self._fd = -1
        self._rewrite()

    def add(self, run: SweepRun) -> None:
        """Appends ``run``'s row; the whole file again when it brings a new metric."""
        self._runs.append(run)
        if any(name not in self._metrics for name in run.scalars):
            self._metrics = _metrics(self._runs)
            self._rewrite()
            return
        os.write(self._fd, _line(_cells(self._plan, run, self._metrics)).encode("utf-8"))
        if self._now() - self._synced >= _SYNC_PERIOD:
            os.fsync(self._fd)
            self._synced = self._now()

    def close(self) -> None:
        """Flushes the rows to disk and closes the file. Idempotent."""
        fd, self._fd = self._fd, -1
        if fd >= 0:
            try:
                os.fsync(fd)
            finally:
                os.close(fd)

    def _rewrite(self) -> None:
        self.close()
        write_runs_csv(self._plan, self._runs, self._path)
        self._fd = os.open(self._path, os.O_WRONLY | os.O_APPEND)
        self._synced = self._now()


def read_runs(path: Path, plan: SweepPlan) -> list[SweepRun]:
    """The runs of ``plan`` that ``path`` (a ``runs.csv``) holds; none if it is missing.

    A last line without its line break (torn by a crash) is left out; a run
    listed twice counts once (its first row).

    Raises:
        ScenarioError: on key ``--resume``: the file is not this sweep's, or a
            row is not one of its runs.
    """
    try:
        text = path.read_text("utf-8")
    except FileNotFoundError:
        return []
    except (OSError, UnicodeDecodeError) as error:
        raise _refused(f"cannot read {path}: {error}") from None
    torn = bool(text) and not text.endswith("\n")
    rows = list(csv.reader(io.StringIO(text, newline="")))
    if not rows:
        return []
    keys = [axis.key for axis in plan.axes]
    header, *rows = rows
    fixed = len(keys) + len(_FIXED)
    if header[:fixed] != [*keys, *_FIXED]:
        expected = ",".join([*keys, *_FIXED])
        raise _refused(f"{path} is not this sweep's: its columns do not start {expected}")
    metrics = header[fixed:]
    points = {plan.labels(point): point for point in range(len(plan.points))}
    runs: dict[tuple[int, int], SweepRun] = {}
    for number, row in enumerate(rows, start=2):
        try:
            run = _run(row, points, plan.seeds, len(keys), metrics)
        except ValueError as error:
            if torn and number == len(rows) + 1:
                break
            raise _refused(f"{path} line {number}: {error}") from None
        runs.setdefault((run.point, run.seed), run)
    return list(runs.values())


def _run(
    row: list[str],
    points: dict[tuple[str, ...], int],
    seeds: int,
    axes: int,
    metrics: list[str],
) -> SweepRun:
    if len(row) != axes + len(_FIXED) + len(metrics):
        raise ValueError(f"expected {axes + len(_FIXED) + len(metrics)} cells, got {len(row)}")
    labels, (seed_text, status_text, error), figures = (
        tuple(row[:axes]),
        row[axes : axes + len(_FIXED)],
        row[axes + len(_FIXED) :],
    )
    if labels not in points:
        raise ValueError(f"{', '.join(labels)} is not a point of this sweep")
    if not seed_text.isdigit() or not 1 <= int(seed_text) <= seeds:
        raise ValueError(f"seed {seed_text!r} is not one of this sweep's, 1 to {seeds}")
    try:
        status = RunStatus(status_text)
    except ValueError:
        raise ValueError(f"{status_text!r} is not a run's status") from None
    scalars = {name: float(cell) for name, cell in zip(metrics, figures, strict=True) if cell}
    return SweepRun(points[labels], int(seed_text), status, error or None, scalars)


def _refused(message: str) -> ScenarioError:
    return ScenarioError([("--resume", message)])


def _metrics(runs: Iterable[SweepRun]) -> list[str]:
    """Every figure's name, in the order first seen."""
    return list(dict.fromkeys(name for run in runs for name in run.scalars))


def _text(plan: SweepPlan, runs: Iterable[SweepRun], metrics: Sequence[str]) -> str:
    keys = [axis.key for axis in plan.axes]
    lines = [_line([*keys, *_FIXED, *metrics])]
    lines += (_line(_cells(plan, run, metrics)) for run in runs)
    return "".join(lines)


def _cells(plan: SweepPlan, run: SweepRun, metrics: Sequence[str]) -> list[str]:
    figures = [_figure(run.scalars[name]) if name in run.scalars else "" for name in metrics]
    return [*plan.labels(run.point), str(run.seed), str(run.status), run.error or "", *figures]


def _figure(value: float) -> str:
    # repr: the shortest text that reads back as the same float (nan and inf too)
    return repr(float(value))


def _line(cells: Sequence[str]) -> str:
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerow(cells)
    return out.getvalue()
