"""The sweep's own worker processes on this machine: the default back end.

A ``ProcessPoolExecutor`` started with ``spawn`` (the parent may hold an event
loop or threads, which ``fork`` would copy half-way), on the first run. Workers
ignore SIGINT: a terminal's Ctrl-C reaches every process of the group, and only
the parent decides what it means. They are started with SIGINT and SIGTERM
blocked until they ignore SIGINT, so that a Ctrl-C while they start prints no
``KeyboardInterrupt`` of theirs. Stopping a sweep kills them: a run is never
waited for.

A worker that dies (killed, out of memory, a run that ends the process) breaks
the whole pool, and the stdlib fails every run in flight with it. The pool tells
the runs apart: each worker notes in shared memory which run it is running, so
the run whose worker died is known, and is run once more (in a fresh pool); if
its worker dies again, it is recorded ``failed`` with the reason. The runs that
were only in flight beside it are run again without counting.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import os
import signal
import time
from collections.abc import Collection, Iterator, Mapping
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.process import BaseProcess
from multiprocessing.sharedctypes import Synchronized
from typing import Any, Final, final

from ..output._results import RunStatus
from ._backend import RunFuture, Settled, settle_plainly
from ._job import SweepJob, run_job
from ._outcome import SweepRun

__all__ = ["LocalPool"]

_KILL_WAIT: Final = 5.0
"""Wall seconds to wait for a killed worker to be gone (it takes milliseconds)."""
_SIGNALS: Final = (signal.SIGINT, signal.SIGTERM)
_DEATHS: Final = 2
"""A run whose worker died this many times is recorded as failed."""
_IDLE: Final = -1

# In a worker: its slot in the pool's table of (pid, run ordinal) pairs.
_table: Any = None
_slot: int = -1


@final
class LocalPool:
    """``jobs`` worker processes of the sweep's own, started on the first run.

    ``ProcessPoolExecutor`` only lets its workers finish what they run; to end
    them now, this keeps their process objects: the children that appeared while
    the pool started them (``multiprocessing.active_children()``).
    """

    def __init__(self, jobs: int) -> None:
        self._jobs = jobs
        self._pool: ProcessPoolExecutor | None = None
        self._table: Any = None  # per worker: its pid and the ordinal of its run
        self._processes: set[BaseProcess] = set()
        self._others: set[BaseProcess] = set()
        self._deaths: dict[int, int] = {}  # by run ordinal
        self.described = f"{jobs} worker process{'es' if jobs != 1 else ''}"
        self.workers_lost = 0
        self.runs_resent = 0

    def window(self) -> int:
        """``jobs``: so that stopping cancels little."""
        return self._jobs

    def running(self, handed_out: int) -> int:
        """All of them: no more are handed out than there are workers."""
        return handed_out

    def workers(self) -> int | None:
        """Fixed: not shown."""
        return None

    def submit(self, job: SweepJob) -> RunFuture:
        """Hands ``job`` to a worker, starting the pool (again) if needed."""
        if self._pool is None:
            context = multiprocessing.get_context("spawn")
            self._others = set(multiprocessing.active_children())
            self._table = context.RawArray(ctypes.c_int64, 2 * self._jobs)
            self._pool = ProcessPoolExecutor(
                self._jobs,
                mp_context=context,
                initializer=_worker_started,
                initargs=(self._table, context.Value(ctypes.c_int, 0)),
            )
        try:
            with _signals_blocked():  # the pool starts a worker here when none is idle
                future = self._pool.submit(_run_here, job)
        except BrokenProcessPool as error:  # it broke since the last look: settled with it
            future = Future()
            future.set_exception(error)
        self._processes.update(set(multiprocessing.active_children()) - self._others)
        return future

    def settle(
        self, future: RunFuture, job: SweepJob, in_flight: Mapping[RunFuture, SweepJob]
    ) -> Settled:
        """The run; after a worker died, every run in flight, failed or to run again."""
        if future.cancelled() or not isinstance(future.exception(), BrokenProcessPool):
            return settle_plainly(future, "a worker process")
        culprits = self._culprits()
        self.discard()
        self.workers_lost += 1
        finished: list[SweepRun] = []
        again: list[SweepJob] = []
        down = [job]
        for other, each in in_flight.items():
            if other.done() and not other.cancelled() and other.exception() is None:
                finished.append(other.result())  # it finished just before the pool broke
            else:
                down.append(each)
        for each in sorted(down, key=lambda job: job.ordinal):
            if each.ordinal not in culprits:
                again.append(each)
                continue
            deaths = self._deaths[each.ordinal] = self._deaths.get(each.ordinal, 0) + 1
            if deaths < _DEATHS:
                again.append(each)
                continue
            reason = (
                f"its worker process died {deaths} times while running it "
                f"(the last time {culprits[each.ordinal]})"
            )
            finished.append(SweepRun(each.point, each.seed, RunStatus.FAILED, reason, {}))
        self.runs_resent += len(again)
        return Settled(tuple(finished), tuple(again), tuple(in_flight))

    def abandon(self, futures: Collection[RunFuture]) -> None:
        """Kills the workers: the runs in flight are given up."""
        self.discard()

    def close(self) -> None:
        """Every run has finished: the workers are told to end, and waited for."""
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True)
        self._processes.clear()

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

    def _culprits(self) -> dict[int, str]:
        """The runs (by ordinal) whose worker died, and how it ended; the pool just broke.

        The stdlib terminates (SIGTERM) the other workers once one has died: a
        worker that ended otherwise is one that died. If none did (one was sent
        SIGTERM from outside), every worker that was running a run may have been
        the one: each of their runs counts a death.
        """
        running = {
            int(self._table[2 * k]): int(self._table[2 * k + 1])
            for k in range(self._jobs)
            if self._table[2 * k] and self._table[2 * k + 1] != _IDLE
        }
        # Every worker is ending (the stdlib ends the others): wait for their exit codes,
        # which the one that died may not have yet when its pool already knows.
        deadline = time.monotonic() + _KILL_WAIT
        for process in self._processes:
            process.join(max(0.0, deadline - time.monotonic()))
        ended = {process.pid: process.exitcode for process in self._processes}
        died = {
            pid: code
            for pid, code in ended.items()
            if pid in running and code is not None and code != -signal.SIGTERM
        }
        if not died:
            died = {pid: -signal.SIGTERM for pid in running}
        return {running[pid]: _how_it_ended(code) for pid, code in died.items()}


def _how_it_ended(code: int) -> str:
    """``"killed by SIGKILL: out of memory?"``, ``"it exited with code 3"``."""
    if code >= 0:
        return f"it exited with code {code}"
    try:
        name = signal.Signals(-code).name
    except ValueError:
        return f"killed by signal {-code}"
    return f"killed by {name}" + (": out of memory?" if -code == signal.SIGKILL else "")


def _worker_started(table: Any, taken: Synchronized[int]) -> None:
    """A worker's first act: SIGINT is the parent's to act on, SIGTERM ends the worker.

    It takes the next slot of ``table``, where it notes its pid and its run.
    """
    global _table, _slot
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if hasattr(signal, "pthread_sigmask"):  # POSIX: born blocked, see _signals_blocked
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _SIGNALS)
    with taken.get_lock():
        _slot = taken.value
        taken.value += 1
    if 2 * _slot < len(table):  # the stdlib never starts more workers than asked
        _table = table
        table[2 * _slot + 1] = _IDLE
        table[2 * _slot] = os.getpid()


def _run_here(job: SweepJob) -> SweepRun:
    """In a worker: :func:`~._job.run_job`, noted in the pool's table while it runs."""
    if _table is not None:
        _table[2 * _slot + 1] = job.ordinal
    try:
        return run_job(job)
    finally:
        if _table is not None:
            _table[2 * _slot + 1] = _IDLE


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
