"""A Dask cluster as a sweep's back end: runs go to the workers of a ``distributed.Client``.

Each run is a task, ``run_job(job)``, under a key that names it
(``cas-sweep-<token>-p<point>-s<seed>``: readable on Dask's dashboard, and
unique to this sweep, since a key the client already holds would return that
task's future instead of a new one). Its result comes back through Dask: no
shared filesystem. About twice as many runs as the cluster has threads are
handed out at a time: every worker has its next run waiting, the grid's order
holds, and stopping cancels little.

Dask runs a lost worker's runs on the others by itself; the sweep only counts
them (the scheduler's ``remove-worker`` events on the ``all`` topic). A run whose
workers kept dying (``distributed.scheduler.allowed-failures`` + 1 times) comes
back as ``KilledWorker``: a ``failed`` run. A run cancelled that the sweep did
not cancel means the connection to the scheduler is lost: the sweep stops, and
keeps what finished.

``distributed`` is imported by whoever made the client: nothing here imports it.
"""

from __future__ import annotations

import contextlib
import queue
import sys
import uuid
from collections.abc import Collection, Mapping
from concurrent.futures import CancelledError
from typing import TYPE_CHECKING, Any, Final, TypeGuard, cast, final

from ..output._results import RunStatus
from ._backend import Refused, RunFuture, Settled, settle_plainly
from ._job import SweepJob, error_text, run_job
from ._outcome import SweepRun

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["DaskBackend", "is_dask_client"]

_RUNS_PER_THREAD: Final = 2
_TOPIC: Final = "all"
"""The scheduler's topic of every event, which tells of workers added and removed."""


def is_dask_client(executor: object) -> TypeGuard[Client]:
    """Whether ``executor`` is a ``distributed.Client`` (without importing Dask)."""
    module = sys.modules.get("distributed")
    return module is not None and isinstance(executor, module.Client)


@final
class DaskBackend:
    """Runs a sweep on the cluster of ``client``, which stays the caller's.

    While the sweep runs, the client's handler of the scheduler's ``all`` topic
    is the sweep's.

    Args:
        client: a connected ``distributed.Client``.
        window: runs to hand out at a time (``None``: twice the cluster's threads).
    """

    def __init__(self, client: Client, window: int | None) -> None:
        self._client: Any = cast(Any, client)  # distributed's methods are not all annotated
        self._fixed = window
        self._prefix = f"cas-sweep-{uuid.uuid4().hex[:8]}-"
        self._events: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._threads = 0
        self._workers = 0
        self._stale = True
        self.address = str(getattr(self._client.scheduler, "address", None) or "?")
        self.workers_lost = 0
        self.runs_resent = 0
        self.most_workers = 0
        self._client.subscribe_topic(_TOPIC, self._events.put)  # called in its own thread
        self._refresh()

    @property
    def described(self) -> str:
        """``"2 Dask workers at tcp://10.0.0.5:8786"``: the most there were at a time."""
        count = self.most_workers
        return f"{count} Dask worker{'s' if count != 1 else ''} at {self.address}"

    def window(self) -> int:
        """``window``, or twice the threads of the workers there are now (2 at least)."""
        self._refresh()
        if self._fixed is not None:
            return self._fixed
        return _RUNS_PER_THREAD * max(1, self._threads)

    def running(self, handed_out: int) -> int:
        """As many as there are threads, at most."""
        return min(handed_out, self._threads)

    def workers(self) -> int | None:
        """The workers the scheduler has now."""
        self._refresh()
        return self._workers

    def submit(self, job: SweepJob) -> RunFuture:
        """A task of ``run_job(job)`` under a key of its own."""
        if not self._connected():
            raise Refused(self._lost())
        key = f"{self._prefix}p{job.point}-s{job.seed}"
        future: RunFuture = self._client.submit(run_job, job, key=key, pure=False)
        return future

    def settle(
        self, future: RunFuture, job: SweepJob, in_flight: Mapping[RunFuture, SweepJob]
    ) -> Settled:
        """The run; ``failed`` when its workers kept dying; a stop when cut off."""
        try:  # its result (or error) is fetched from the cluster: the connection may go
            if future.cancelled():
                raise CancelledError(future)
            error = future.exception()
            run: SweepRun | None = future.result() if error is None else None
        except Exception as lost:  # a cancellation, or the connection closed
            if not self._connected() or _connection_lost(lost):
                return Settled(stop=self._lost())
            if isinstance(lost, CancelledError):
                return Settled(stop="the Dask cluster cancelled a run that the sweep had not")
            return Settled(stop=f"the Dask cluster did not give a run back: {error_text(lost)}")
        if run is not None:
            return Settled(finished=(run,))
        if type(error).__name__ == "KilledWorker":
            tries = error.args[2] + 1 if error is not None and len(error.args) > 2 else "several"
            reason = f"its worker died {tries} times while running it (killed, or out of memory?)"
            return Settled(finished=(SweepRun(job.point, job.seed, RunStatus.FAILED, reason, {}),))
        return settle_plainly(future, "the Dask cluster")

    def abandon(self, futures: Collection[RunFuture]) -> None:
        """Cancels the runs not finished (those running finish unseen on their workers)."""
        if futures and self._connected():
            with contextlib.suppress(Exception):  # lost meanwhile: nothing to cancel
                self._client.cancel(list(futures))
        self.close()

    def close(self) -> None:
        """Stops listening to the scheduler's events (once it has read those that came)."""
        self._refresh()
        if self._connected():
            # before the client closes, else the scheduler logs a failed write to it
            with contextlib.suppress(Exception):
                self._client.unsubscribe_topic(_TOPIC)

    def _connected(self) -> bool:
        return bool(self._client.status == "running")

    def _lost(self) -> str:
        return f"lost the connection to the Dask scheduler at {self.address}"

    def _refresh(self) -> None:
        """Reads the events, and the workers' threads again if they changed."""
        while True:
            try:
                _, event = self._events.get_nowait()
            except queue.Empty:
                break
            if not isinstance(event, dict):
                continue
            action = event.get("action")
            if action == "add-worker":
                self._stale = True
            elif action == "remove-worker":
                self._stale = True
                if not event.get("expected", False):
                    self.workers_lost += 1
                sent_again = {
                    key
                    for key in (
                        *event.get("processing-tasks", ()),
                        *event.get("lost-computed-tasks", ()),
                    )
                    if isinstance(key, str) and key.startswith(self._prefix)
                }
                self.runs_resent += len(sent_again)
        if self._stale and self._connected():
            self._stale = False
            with contextlib.suppress(Exception):  # lost meanwhile: the futures will say
                threads = self._client.nthreads()
                self._threads = sum(threads.values())
                self._workers = len(threads)
                self.most_workers = max(self.most_workers, self._workers)


def _connection_lost(error: BaseException) -> bool:
    """Whether fetching a run failed because the scheduler went.

    The client's status says so only once its own stream to the scheduler noticed,
    which on a loaded machine may come after a fetch of a result failed (a closed
    comm is an ``OSError``) or the client cancelled its futures for that reason.
    """
    return isinstance(error, OSError) or getattr(error, "reason", None) == (
        "scheduler-connection-lost"
    )
