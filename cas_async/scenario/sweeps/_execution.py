"""Experiment sweeps: a scenario over a grid of values and seeds, in parallel processes.

:func:`sweep` does it all: :func:`~._sweep_grid.plan_sweep` checks the grid,
:func:`run_sweep` runs it, then the outputs are written (:mod:`._sweep_report`,
:mod:`._sweep_plots`). ``python -m cas_async sweep`` is these steps with signals handled.

Each run goes to a worker process (``spawn``: the parent may hold an event loop
or threads, which ``fork`` would copy half-way), loads its scenario, runs it to
its end and sends back a :class:`~._sweep_results.SweepRun`: its status and its
figures, never its trace. Workers write no files and print no progress (the
runtime's log records, such as a failing layer's traceback, reach stderr as in
``run``). At most ``jobs`` runs are handed out at a time, so that stopping cancels little.

Workers ignore SIGINT: a terminal's Ctrl-C reaches every process of the group,
and only the parent decides what it means. They are started with SIGINT and
SIGTERM blocked until they ignore SIGINT, so that a Ctrl-C while they start
prints no ``KeyboardInterrupt`` of theirs. Stopping a sweep (``stop``, or an
exception such as ``KeyboardInterrupt`` in the parent) cancels the runs not
started and kills the workers: a run is never waited for.

A worker that dies (killed, out of memory) breaks its pool: the runs it had in
flight with it are recorded as failed, and the sweep goes on in a fresh pool.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import Final, TextIO, final

from ..._time._loop_factory import run
from .._run._run_scenario import run_scenario
from .._spec._loader import load_scenario
from ..output._results import RunStatus
from ._box_plots import write_box_plots
from ._files import format_number, write_sweep_files
from ._outcome import SweepOutcome, SweepRun
from ._plan import SweepAxis, SweepPlan, plan_sweep

__all__ = ["run_sweep", "sweep"]

_POLL: Final = 0.1
"""Wall seconds between two looks at ``stop`` while runs are under way."""
_KILL_WAIT: Final = 5.0
"""Wall seconds to wait for a killed worker to be gone (it takes milliseconds)."""
_SIGNALS: Final = (signal.SIGINT, signal.SIGTERM)
_BROKEN: Final = (
    "a worker process died (killed, or out of memory?) while this run was in flight; "
    "the runs in flight with it are reported the same way"
)


def sweep(
    path: str | os.PathLike[str],
    *,
    seeds: int,
    vary: Sequence[str | SweepAxis] = (),
    overrides: Sequence[str] = (),
    jobs: int | None = None,
    out: str | os.PathLike[str] | None = None,
    plots: bool = True,
    progress_to: TextIO | None = None,
) -> SweepOutcome:
    """Runs ``path`` at every point of the grid with seeds ``1..seeds``; writes the outputs.

    As ``python -m cas_async sweep``. The worker processes are started with
    ``spawn``: in a script, call this under ``if __name__ == "__main__":``.

    Args:
        path: the scenario file.
        seeds: runs per point.
        vary: the axes, as ``--vary`` texts (``"strategy.name=time,solo"``) or parsed.
        overrides: ``--set`` texts.
        jobs: worker processes (default: ``os.cpu_count()``).
        out: where to write ``runs.csv``, ``table.md``, ``summary.json`` and the
            box plots; ``None`` writes nothing.
        plots: draw the box plots (with ``out``).
        progress_to: where to write a line per finished run and a last one.

    Raises:
        ScenarioError: the sweep or a point's scenario is not valid (nothing ran).
        ValueError: ``jobs`` is less than 1.
    """
    plan = plan_sweep(path, seeds=seeds, vary=vary, overrides=overrides)
    outcome = run_sweep(plan, jobs=jobs, progress_to=progress_to)
    if out is not None:
        write_sweep_files(outcome, Path(out))
        if plots:
            write_box_plots(outcome, Path(out))
    return outcome


def run_sweep(
    plan: SweepPlan,
    *,
    jobs: int | None = None,
    progress_to: TextIO | None = None,
    stop: Callable[[], bool] | None = None,
) -> SweepOutcome:
    """Runs every run of ``plan`` in ``jobs`` worker processes; returns what finished.

    Args:
        plan: what to run (see :func:`~cas_async.scenario.sweeps.plan_sweep`).
        jobs: worker processes (default: ``os.cpu_count()``); never more than runs.
        progress_to: where to write a line per finished run, and one at the end.
        stop: asked about ten times a second; once it returns true, the runs not
            finished are abandoned (the workers killed) and the outcome says
            ``interrupted``. It may be a signal's flag; it must not block.

    Raises:
        ValueError: ``jobs`` is less than 1.
    """
    jobs = (os.cpu_count() or 1) if jobs is None else jobs
    if jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs}")
    jobs = min(jobs, plan.runs)
    started = time.perf_counter()
    waiting = [
        (point, seed) for point in range(len(plan.points)) for seed in range(1, plan.seeds + 1)
    ][::-1]  # popped from the end: by point, then seed
    finished: list[SweepRun] = []
    in_flight: dict[Future[SweepRun], _Job] = {}
    interrupted = False

    def record(done: SweepRun) -> None:
        finished.append(done)
        if progress_to is not None:
            print(f"[{len(finished)}/{plan.runs}] {_progress(plan, done)}", file=progress_to)
            progress_to.flush()

    with _Workers(jobs) as workers:
        while waiting or in_flight:
            if stop is not None and stop():
                interrupted = True
                for future in in_flight:  # what finished since the last look
                    if future.done() and not future.cancelled() and future.exception() is None:
                        record(future.result())
                workers.discard()
                break
            broken = False
            while waiting and len(in_flight) < jobs and not broken:
                point, seed = waiting.pop()
                job = _Job(os.fspath(plan.path), (*plan.run_overrides(point, seed),), point, seed)
                try:
                    in_flight[workers.submit(job)] = job
                except BrokenProcessPool:  # it broke since the last look: the job waits
                    waiting.append((point, seed))
                    broken = True
            done, _ = wait(in_flight, timeout=_POLL, return_when=FIRST_COMPLETED)
            if broken or any(_broke(future) for future in done):
                # every run in flight goes down with the pool: record them all, start afresh
                done = set(in_flight)
                workers.discard()
            for future in done:
                job = in_flight.pop(future)
                record(_finished(future, job))
    outcome = SweepOutcome(
        plan,
        tuple(sorted(finished, key=lambda done: (done.point, done.seed))),
        time.perf_counter() - started,
        jobs,
        interrupted,
    )
    if progress_to is not None:
        print(_last_line(outcome), file=progress_to)
        progress_to.flush()
    return outcome


@dataclass(frozen=True, slots=True)
class _Job:
    """One run, as a worker gets it."""

    path: str
    overrides: tuple[str, ...]
    point: int
    seed: int


def _run_one(job: _Job) -> SweepRun:
    """In a worker: loads and runs one scenario; the trace stays here."""
    started = time.perf_counter()
    try:
        scenario = load_scenario(job.path, job.overrides)
        result, _trace = run(run_scenario(scenario), virtual=scenario.run.virtual)
    except Exception as error:  # a failing layer fails the run by itself: this is anything else
        wall = {"wall_time": time.perf_counter() - started}
        return SweepRun(job.point, job.seed, RunStatus.FAILED, _error_text(error), wall)
    return SweepRun(job.point, job.seed, result.status, result.error, result.scalars())


def _broke(future: Future[SweepRun]) -> bool:
    """Whether ``future`` (done) failed because its pool broke: a worker died."""
    return not future.cancelled() and isinstance(future.exception(), BrokenProcessPool)


def _finished(future: Future[SweepRun], job: _Job) -> SweepRun:
    """The run ``future`` made; a failed run when its worker could not say, or died.

    ``future`` may be unfinished (or cancelled) when its pool broke: it never waits.
    """
    text = _BROKEN
    if future.done() and not future.cancelled():
        error = future.exception()
        if error is None:
            return future.result()
        if not isinstance(error, BrokenProcessPool):
            text = _error_text(error)
    return SweepRun(job.point, job.seed, RunStatus.FAILED, text, {})


def _error_text(error: BaseException) -> str:
    return f"{type(error).__name__}: {error}"


def _worker_started() -> None:
    """A worker's first act: SIGINT is the parent's to act on, SIGTERM ends the worker."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if hasattr(signal, "pthread_sigmask"):  # POSIX: born blocked, see _signals_blocked
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGNALS)


@contextlib.contextmanager
def _signals_blocked() -> Iterator[None]:
    """Processes started within are born with SIGINT and SIGTERM blocked (POSIX).

    A signal for this thread meanwhile waits, and is handled as the block ends.
    """
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    before = signal.pthread_sigmask(signal.SIG_BLOCK, _SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)


@final
class _Workers:
    """The sweep's process pool, started on the first run, which can be dropped at once.

    ``ProcessPoolExecutor`` only lets its workers finish what they run; to end
    them now, this keeps their process objects: the children that appeared while
    the pool started them (``multiprocessing.active_children()``).
    """

    def __init__(self, jobs: int) -> None:
        self._jobs = jobs
        self._pool: ProcessPoolExecutor | None = None
        self._processes: set[BaseProcess] = set()
        self._others: set[BaseProcess] = set()

    def __enter__(self) -> _Workers:
        return self

    def __exit__(self, *exc_info: object) -> None:
        if exc_info[0] is None:
            self._close()
        else:  # KeyboardInterrupt or worse: nobody waits for the runs
            self.discard()

    def submit(self, job: _Job) -> Future[SweepRun]:
        """Hands ``job`` to a worker, starting the pool (again) if needed."""
        if self._pool is None:
            self._others = set(multiprocessing.active_children())
            self._pool = ProcessPoolExecutor(
                self._jobs,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_worker_started,
            )
        with _signals_blocked():  # the pool starts a worker here when none is idle
            future = self._pool.submit(_run_one, job)
        self._processes.update(set(multiprocessing.active_children()) - self._others)
        return future

    def discard(self) -> None:
        """Cancels the runs not started and kills the workers; the next submit starts anew."""
        pool, self._pool = self._pool, None
        if pool is None:
            return
        pool.shutdown(wait=False, cancel_futures=True)
        processes, self._processes = self._processes, set()
        for process in processes:
            # SIGKILL: a worker still starting has SIGTERM blocked; none has anything to save
            process.kill()
        for process in processes:
            process.join(_KILL_WAIT)

    def _close(self) -> None:
        """Every run has finished: the workers are told to end, and waited for."""
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True)
        self._processes.clear()


def _progress(plan: SweepPlan, done: SweepRun) -> str:
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


def _last_line(outcome: SweepOutcome) -> str:
    plan = outcome.plan
    done = len(outcome.runs)
    completed = done - len(outcome.incomplete)
    ran = f"interrupted after {done} of {plan.runs} runs" if outcome.interrupted else f"{done} runs"
    processes = f"{outcome.jobs} worker process{'es' if outcome.jobs != 1 else ''}"
    return f"sweep: {ran} ({completed} completed) in {outcome.wall_time:.1f} s wall, {processes}"
