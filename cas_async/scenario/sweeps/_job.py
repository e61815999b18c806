"""One run of a sweep as a worker gets it, and what the worker does with it.

A :class:`SweepJob` carries the run's scenario *content* (the file and what it
extends, every override applied), not a path: a worker on another host needs no
shared filesystem, only cas_async and the application installed. It is small
(about 600 bytes for the Fire Brigade) and made of plain values, so that any
executor can send it. :func:`run_job` runs it to its end and returns a
:class:`~._outcome.SweepRun`: its status and its figures, never its trace.

Whatever goes wrong *in* the run is the run's: a failing layer fails it (the
runtime's error), anything else it raises, ``SystemExit`` included, makes it a
``failed`` run with the reason. What goes wrong *around* it is the worker's:
scenario data that its copy of the application refuses (another version, or
none installed) raises :class:`UnfitWorker`, which stops the sweep, since
every other run would fail the same way.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..._time._loop_factory import run
from .._run._run_scenario import run_scenario
from .._spec._config import ScenarioError
from .._spec._loader import scenario_from_data
from ..output._results import RunStatus
from ._outcome import SweepRun

__all__ = ["SweepJob", "UnfitWorker", "error_text", "run_job"]


@dataclass(frozen=True, slots=True)
class SweepJob:
    """One run of a sweep: where it is in the grid and what to run.

    Attributes:
        ordinal: its place in the sweep's order (by point, then seed), from 0.
        point: its point, an index into :attr:`SweepPlan.points`.
        seed: its seed.
        path: the scenario file, resolved: for messages, and for an ``app`` or a
            ``[layers]`` class that sits beside it (found where the same
            checkout is at the same path).
        data: the run's scenario data, ``run.seed`` included.
    """

    ordinal: int
    point: int
    seed: int
    path: str
    data: dict[str, Any]


class UnfitWorker(Exception):
    """A worker could not load a run that loaded where the sweep was planned.

    The plan loaded every point before any run, so the scenario is valid: the
    worker's environment is not (the application missing, or another version of
    it or of cas_async).
    """

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message

    def __reduce__(self) -> tuple[Any, ...]:
        return type(self), (self.message,)


def run_job(job: SweepJob) -> SweepRun:
    """In a worker: runs ``job`` to its end; its trace stays here.

    Raises:
        UnfitWorker: this worker cannot load the run's scenario.
    """
    started = time.perf_counter()
    try:
        scenario = scenario_from_data(Path(job.path), job.data)
    except ScenarioError as error:
        raise UnfitWorker(f"a worker cannot load the scenario: {error}") from None
    try:
        result, _trace = run(run_scenario(scenario), virtual=scenario.run.virtual)
    except (Exception, SystemExit) as error:  # a failing layer fails the run by itself
        wall = {"wall_time": time.perf_counter() - started}
        reason = error_text(error)
        if isinstance(error, SystemExit):
            reason = f"the run exited: {reason}"
        return SweepRun(job.point, job.seed, RunStatus.FAILED, reason, wall)
    # floats, so that runs.csv reads back as written (an app's metric may be an int)
    figures = {name: float(value) for name, value in result.scalars().items()}
    return SweepRun(job.point, job.seed, result.status, result.error, figures)


def error_text(error: BaseException) -> str:
    """``"RuntimeError: the message"``: an exception's type and message."""
    return f"{type(error).__name__}: {error}"
