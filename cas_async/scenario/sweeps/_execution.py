"""Running a sweep: every run of a plan, handed to workers, recorded as it finishes.

:func:`sweep` does it all: :func:`~._plan.plan_sweep` checks the grid,
:func:`run_sweep` runs it, then the outputs are written (:mod:`._files`,
:mod:`._box_plots`). ``python -m cas_async sweep`` is these steps with signals handled.

Where the runs run is a back end (:mod:`._backend`): the sweep's own worker
processes on this machine (:mod:`._local_pool`, the default), a Dask cluster
(:mod:`._dask`, given a ``distributed.Client``), or any
``concurrent.futures.Executor``. Each run goes out as a :class:`~._job.SweepJob`
(its scenario's content, not a path) and comes back a
:class:`~._outcome.SweepRun`: its status and its figures, never its trace.
Workers write no files and print no progress (the runtime's log records, such as
a failing layer's traceback, reach their stderr as in ``run``).

Nothing finished is lost. Given an output folder, the sweep writes
``sweep.json`` (:mod:`._manifest`) before its first run, then a row of
``runs.csv`` (:mod:`._runs_file`) as each run finishes: a sweep stopped at any
moment leaves every finished run there, and a resumed one runs only the others.
The loop looks at ``stop`` ten times a second; stopping (or an exception such as
``KeyboardInterrupt``) gives up the runs not finished, never waits for one.
"""

from __future__ import annotations

import os
import queue
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from pathlib import Path
from typing import TYPE_CHECKING, Final, TextIO, final

from ._backend import Backend, ExecutorBackend, Refused, RunFuture
from ._box_plots import write_box_plots
from ._dask import DaskBackend, is_dask_client
from ._display import SweepDisplay
from ._files import write_sweep_files
from ._job import SweepJob
from ._local_pool import LocalPool
from ._manifest import check_resume, write_manifest
from ._outcome import SweepOutcome, SweepRun
from ._plan import SweepAxis, SweepPlan, plan_sweep
from ._runs_file import RunsFile, read_runs, write_runs_csv

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["run_sweep", "sweep"]

_POLL: Final = 0.1
"""Wall seconds between two looks at ``stop`` while runs are under way."""
_RUNS: Final = "runs.csv"


def sweep(
    path: str | os.PathLike[str],
    *,
    seeds: int,
    vary: Sequence[str | SweepAxis] = (),
    overrides: Sequence[str] = (),
    jobs: int | None = None,
    executor: Executor | Client | None = None,
    out: str | os.PathLike[str] | None = None,
    resume: bool = False,
    plots: bool = True,
    progress_to: TextIO | None = None,
) -> SweepOutcome:
    """Runs ``path`` at every point of the grid with seeds ``1..seeds``; writes the outputs.

    As ``python -m cas_async sweep``. Without ``executor`` the runs go to worker
    processes started with ``spawn``: in a script, call this under
    ``if __name__ == "__main__":``.

    Args:
        path: the scenario file.
        seeds: runs per point.
        vary: the axes, as ``--vary`` texts (``"strategy.name=time,solo"``) or parsed.
        overrides: ``--set`` texts.
        jobs: worker processes (default: ``os.cpu_count()``); with ``executor``,
            the runs handed to it at a time (see :func:`run_sweep`).
        executor: where to run instead (see :func:`run_sweep`).
        out: where to write ``sweep.json``, ``runs.csv`` (as the runs finish),
            ``table.md``, ``summary.json`` and the box plots; ``None`` writes nothing.
        resume: run only the runs that ``out`` does not hold yet.
        plots: draw the box plots (with ``out``).
        progress_to: where to show progress and a last line.

    Raises:
        ScenarioError: the sweep or a point's scenario is not valid, or ``out``
            holds another sweep than the one to resume (nothing ran).
        ValueError: ``jobs`` is less than 1, or ``resume`` without ``out``.
    """
    plan = plan_sweep(path, seeds=seeds, vary=vary, overrides=overrides)
    outcome = run_sweep(
        plan,
        jobs=jobs,
        executor=executor,
        out=out,
        resume=resume,
        progress_to=progress_to,
    )
    if out is not None:
        write_sweep_files(outcome, Path(out))
        if plots:
            write_box_plots(outcome, Path(out))
    return outcome


def run_sweep(
    plan: SweepPlan,
    *,
    jobs: int | None = None,
    executor: Executor | Client | None = None,
    out: str | os.PathLike[str] | None = None,
    resume: bool = False,
    progress_to: TextIO | None = None,
    stop: Callable[[], bool] | None = None,
) -> SweepOutcome:
    """Runs every run of ``plan`` (those not done yet, with ``resume``); returns what finished.

    Args:
        plan: what to run (see :func:`~cas_async.scenario.sweeps.plan_sweep`).
        jobs: worker processes of the sweep's own (default: ``os.cpu_count()``;
            never more than runs). With ``executor``: how many runs are handed
            to it at a time (default: twice a Dask cluster's threads, as its
            workers come and go; for another executor all of them).
        executor: where to run, instead of worker processes of the sweep's own: a
            ``distributed.Client`` (its cluster's workers; the client stays
            yours, and while the sweep runs its handler of the scheduler's
            ``all`` topic is the sweep's) or any ``concurrent.futures.Executor``
            (a process pool, Ray's executor; never shut down here). A run that
            the executor cannot make (it broke, it refused, the connection was
            lost) ends the sweep: the outcome says why (``error``).
        out: a folder (created) where ``sweep.json`` is written before the first
            run and a row of ``runs.csv`` as each run finishes (in its final
            order once the sweep ends); ``None`` writes nothing.
        resume: ``out`` holds an earlier session of this very sweep: its finished
            runs (whatever their status) are kept, and only the others run.
        progress_to: where to show progress (a bar on a terminal, else a line
            per finished run) and a last line.
        stop: asked about ten times a second; once it returns true, the runs not
            finished are abandoned (the sweep's own workers killed) and the
            outcome says ``interrupted``. It may be a signal's flag; it must not block.

    Raises:
        ScenarioError: on key ``--resume``: ``out`` holds no sweep, or another one
            (the message says what changed); nothing ran.
        ValueError: ``jobs`` is less than 1, or ``resume`` without ``out``.
        TypeError: ``executor`` is neither an ``Executor`` nor a ``distributed.Client``.
    """
    if jobs is not None and jobs < 1:
        raise ValueError(f"jobs must be at least 1, got {jobs}")
    folder = Path(out) if out is not None else None
    resumed: list[SweepRun] = []
    note = None
    if resume:
        if folder is None:
            raise ValueError("resume needs out: the folder of the sweep to resume")
        note = check_resume(folder, plan)
        resumed = sorted(read_runs(folder / _RUNS, plan), key=_order)
    done = {(run.point, run.seed) for run in resumed}
    todo = deque(
        (point, seed)
        for point in range(len(plan.points))
        for seed in range(1, plan.seeds + 1)
        if (point, seed) not in done
    )
    backend = _backend(executor, jobs, len(todo))
    display = SweepDisplay(progress_to, plan) if progress_to is not None else None
    runs_file = None
    if folder is not None:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            if not resume:
                write_manifest(folder, plan)
            runs_file = RunsFile(folder / _RUNS, plan, resumed)
        except BaseException:  # nothing ran: the back end lets go of what it holds
            backend.close()
            raise
    if display is not None and folder is not None and resume:
        display.resumed(resumed, folder)
        if note is not None:
            display.note(note)
    loop = _Loop(plan, backend, display, runs_file)
    started = time.perf_counter()
    try:
        interrupted = loop.run(todo, stop)
    finally:
        if runs_file is not None:
            runs_file.close()
    runs = tuple(sorted([*resumed, *loop.finished], key=_order))
    if folder is not None:
        write_runs_csv(plan, runs, folder / _RUNS)
    outcome = SweepOutcome(
        plan,
        runs,
        time.perf_counter() - started,
        loop.most,
        interrupted or loop.error is not None,
        loop.error,
        len(resumed),
        backend.described,
        backend.workers_lost,
        backend.runs_resent,
    )
    if display is not None:
        display.close(outcome)
    return outcome


@final
class _Loop:
    """Hands runs out, keeps ``backend``'s window full, records each run as it finishes."""

    def __init__(
        self,
        plan: SweepPlan,
        backend: Backend,
        display: SweepDisplay | None,
        runs_file: RunsFile | None,
    ) -> None:
        self._plan = plan
        self._backend = backend
        self._display = display
        self._runs_file = runs_file
        self._path = str(plan.path.resolve())
        self._done: queue.SimpleQueue[RunFuture] = queue.SimpleQueue()
        self._in_flight: dict[RunFuture, SweepJob] = {}
        self.finished: list[SweepRun] = []
        self.error: str | None = None
        self.most = 0  # runs handed out at a time, at most

    def run(self, todo: deque[tuple[int, int]], stop: Callable[[], bool] | None) -> bool:
        """Runs ``todo`` (point, seed) in the grid's order; whether ``stop`` ended it."""
        again: deque[SweepJob] = deque()
        seeds = self._plan.seeds
        in_flight = self._in_flight
        try:
            while again or todo or in_flight:
                if stop is not None and stop():
                    self._give_up()
                    return True
                while (again or todo) and len(in_flight) < self._backend.window():
                    if again:
                        job = again.popleft()
                    else:
                        point, seed = todo.popleft()
                        job = SweepJob(
                            point * seeds + seed - 1,
                            point,
                            seed,
                            self._path,
                            self._plan.run_data(point, seed),
                        )
                    try:
                        future = self._backend.submit(job)
                    except Refused as refused:
                        self.error = str(refused)
                        break
                    in_flight[future] = job
                    self.most = max(self.most, len(in_flight))
                    future.add_done_callback(self._done.put)
                if self.error is None:
                    self._settle_next(again)
                if self.error is not None:
                    self._give_up()
                    return False
        except BaseException:  # KeyboardInterrupt or worse: nobody waits for the runs
            self._backend.abandon(list(in_flight))
            raise
        self._backend.close()
        return False

    def _settle_next(self, again: deque[SweepJob]) -> None:
        """Waits a little for a run to finish, and deals with it."""
        try:
            future = self._done.get(timeout=_POLL)
        except queue.Empty:
            if self._display is not None:
                self._display.update(self._running(), self._backend.workers())
            return
        job = self._in_flight.pop(future, None)
        if job is None:  # settled already, with the run that broke its pool
            return
        settled = self._backend.settle(future, job, self._in_flight)
        for other in settled.settled:
            self._in_flight.pop(other, None)
        again.extendleft(reversed(settled.again))
        for run in settled.finished:
            self._record(run)
        self.error = settled.stop

    def _give_up(self) -> None:
        """Records the runs finished since the last look, and abandons the others."""
        for future in list(self._in_flight):
            try:  # a Dask future's result is fetched: its connection may be gone
                run = future.result() if _succeeded(future) else None
            except Exception:  # lost with the rest
                run = None
            if run is not None:
                del self._in_flight[future]
                self._record(run)
        self._backend.abandon(list(self._in_flight))

    def _record(self, run: SweepRun) -> None:
        self.finished.append(run)
        if self._runs_file is not None:
            self._runs_file.add(run)
        if self._display is not None:
            self._display.finished(run, self._running(), self._backend.workers())

    def _running(self) -> int:
        return self._backend.running(len(self._in_flight))


def _backend(executor: Executor | Client | None, jobs: int | None, runs: int) -> Backend:
    if executor is None:
        count = (os.cpu_count() or 1) if jobs is None else jobs
        return LocalPool(max(1, min(count, runs)))
    if is_dask_client(executor):
        return DaskBackend(executor, jobs)
    if isinstance(executor, Executor):
        return ExecutorBackend(executor, jobs)
    raise TypeError(
        "executor: expected a concurrent.futures.Executor or a distributed.Client, "
        f"got {type(executor).__name__}"
    )


def _succeeded(future: RunFuture) -> bool:
    return future.done() and not future.cancelled() and future.exception() is None


def _order(run: SweepRun) -> tuple[int, int]:
    return run.point, run.seed
