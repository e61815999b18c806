"""Where a sweep's runs run: the contract of a back end, and any ``Executor`` behind it.

The sweep's loop (:mod:`._execution`) hands :class:`~._job.SweepJob` records to a
:class:`Backend` and learns what became of each from :meth:`Backend.settle`. Three
back ends keep the contract: the sweep's own local processes (:mod:`._local_pool`,
the default), a Dask ``distributed.Client`` (:mod:`._dask`), and here any
``concurrent.futures.Executor`` (a process pool of the user's, Ray's executor, ...).

A future's callback only puts the future on a queue; everything else happens in
the loop's thread, so a back end needs no lock.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Collection, Mapping
from concurrent.futures import CancelledError, Executor
from dataclasses import dataclass
from typing import Any, Protocol, final

from ._job import SweepJob, UnfitWorker, error_text, run_job
from ._outcome import SweepRun

__all__ = ["Backend", "ExecutorBackend", "Refused", "RunFuture", "Settled"]


class RunFuture(Protocol):
    """What the loop needs of a future: a ``concurrent.futures`` one or a Dask one."""

    def add_done_callback(self, fn: Callable[[Any], object], /) -> None:
        """Calls ``fn(future)`` once it is done (perhaps in another thread)."""

    def done(self) -> bool:
        """Whether it is done (finished, failed or cancelled)."""

    def cancelled(self) -> bool:
        """Whether it was cancelled."""

    def exception(self) -> BaseException | None:
        """What the call raised (the future is done)."""

    def result(self) -> Any:
        """What the call returned (the future is done)."""

    def cancel(self) -> Any:
        """Cancels the call if it has not started."""


@dataclass(frozen=True, slots=True)
class Settled:
    """What a done future (and those that went down with it) came to.

    Attributes:
        finished: runs to record.
        again: runs to hand out again, first.
        settled: other futures in flight that this settles too (a broken pool's).
        stop: why the sweep cannot go on (what finished is kept), or ``None``.
    """

    finished: tuple[SweepRun, ...] = ()
    again: tuple[SweepJob, ...] = ()
    settled: tuple[RunFuture, ...] = ()
    stop: str | None = None


class Refused(Exception):
    """A back end cannot take runs any more; the message says why."""


class Backend(Protocol):
    """Runs a sweep's jobs somewhere; used from the sweep's loop only.

    Attributes:
        workers_lost: worker processes that died while the sweep ran.
        runs_resent: runs handed out again because their worker was lost.
    """

    workers_lost: int
    runs_resent: int

    @property
    def described(self) -> str:
        """Where the runs ran, for people: ``"2 worker processes"``."""

    def window(self) -> int:
        """How many runs to keep handed out: enough to keep every worker busy."""

    def running(self, handed_out: int) -> int:
        """Of ``handed_out`` runs, about how many run now."""

    def workers(self) -> int | None:
        """How many workers there are now, if that may change while the sweep runs."""

    def submit(self, job: SweepJob) -> RunFuture:
        """Hands ``job`` out.

        Raises:
            Refused: the back end takes no more runs.
        """

    def settle(
        self, future: RunFuture, job: SweepJob, in_flight: Mapping[RunFuture, SweepJob]
    ) -> Settled:
        """What the done ``future`` of ``job`` came to; ``in_flight`` holds the others."""

    def abandon(self, futures: Collection[RunFuture]) -> None:
        """Gives up the runs of ``futures`` (not waited for), as the sweep stops."""

    def close(self) -> None:
        """Every run has finished: lets go of what the back end started."""


@final
class ExecutorBackend:
    """Any ``concurrent.futures.Executor``: each run is a call of :func:`~._job.run_job`.

    The executor is the caller's: it is never shut down, and its workers' signals
    are its business. A run it could not make (its pool broke, it raised) stops
    the sweep, as a lost connection does: the runs still to do may be resumed
    with a fresh executor.

    Args:
        executor: where to run.
        window: runs to hand out at a time (``None``: all of them).
    """

    def __init__(self, executor: Executor, window: int | None) -> None:
        self._executor = executor
        self._window = window
        self.described = f"a {type(executor).__name__}"
        self.workers_lost = 0
        self.runs_resent = 0

    def window(self) -> int:
        """``window``, or no limit."""
        return self._window if self._window is not None else sys.maxsize

    def running(self, handed_out: int) -> int:
        """All of them, as far as the sweep can tell."""
        return handed_out

    def workers(self) -> int | None:
        """Not known."""
        return None

    def submit(self, job: SweepJob) -> RunFuture:
        """``executor.submit(run_job, job)``."""
        try:
            return self._executor.submit(run_job, job)
        except Exception as error:  # shut down, broken: whatever it says
            raise Refused(f"the executor took no more runs: {error_text(error)}") from error

    def settle(
        self, future: RunFuture, job: SweepJob, in_flight: Mapping[RunFuture, SweepJob]
    ) -> Settled:
        """The run, or why the executor could not make it."""
        return settle_plainly(future, "the executor")

    def abandon(self, futures: Collection[RunFuture]) -> None:
        """Cancels the runs not started; those running finish unseen."""
        for future in futures:
            future.cancel()

    def close(self) -> None:
        """Nothing: the executor is the caller's."""


def settle_plainly(future: RunFuture, who: str) -> Settled:
    """A done future's run; or why ``who`` (``"the executor"``) could not make it."""
    if future.cancelled():
        return Settled(stop=f"{who} cancelled a run the sweep had not cancelled")
    try:
        error = future.exception()
    except CancelledError as cancelled:  # a Dask future cancelled meanwhile
        return Settled(stop=f"{who} cancelled a run: {cancelled}")
    if error is None:
        run: SweepRun = future.result()
        return Settled(finished=(run,))
    if isinstance(error, UnfitWorker):
        return Settled(stop=f"{error.message}: install the same versions on every worker")
    return Settled(stop=f"{who} could not make a run: {error_text(error)}")
