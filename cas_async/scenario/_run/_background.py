"""A scenario run inside an asyncio service: on a loop of its own, in a worker thread.

A virtual-time run needs the virtual-time loop (it jumps over idle time, which
would stall every other task of a service), and a scaled run should not share a
service's loop with its web requests either. :class:`BackgroundRun` runs a loaded
scenario with :class:`~cas_async.scenario.ScenarioRun` on its own loop (the one
``cas_async.run`` makes for it: virtual time, or uvloop) in a thread of its own,
and gives the service what it needs without making threads:

* ``await run`` (or ``await run.wait()``): the result, without blocking the
  service's loop; the run's error (a scenario the app refuses, say) is raised there;
* :meth:`~BackgroundRun.progress`: where the run stands, from any thread, at any
  moment (a snapshot the run publishes every ``trace_interval`` simulated seconds
  on virtual time, every ``progress_interval`` wall seconds on scaled time, and
  when it ends);
* :meth:`~BackgroundRun.stop`: ends the run early (status INTERRUPTED), from any thread;
* ``async with BackgroundRun(scenario) as run:``: started on entry; leaving the
  block stops the run if it still runs and waits for its end.

The garbage collector's thresholds are the process's: while the run goes, they
are sized to its swarm (see :mod:`~cas_async._core._gc_policy`).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import threading
from collections.abc import Callable, Generator
from typing import Any, final

from ..._errors import RobotStateError
from ..._time._loop_factory import run as run_loop
from ..._wire._swarm_key import SwarmKey
from ...sim._environment import Environment
from .._spec._loader import Scenario
from ..output._results import RunProgress, RunResult
from ..output._trace import Trace
from ._runner import ScenarioRun

__all__ = ["BackgroundRun"]


@final
class BackgroundRun:
    """A scenario run on an event loop of its own in a worker thread (see the module docs).

    ::

        run = BackgroundRun(load_scenario("gathering.toml"))
        run.start()                  # returns at once; the robots are built in the thread
        ...
        run.progress().time          # simulated seconds so far, from any thread
        result = await run           # the RunResult, without blocking this loop

    Args:
        scenario: a loaded scenario (``load_scenario``), on virtual or scaled time.
        key: the swarm key (see :class:`~cas_async.scenario.ScenarioRun`).
        observe: called with the Environment before the robots start, in the
            run's thread.
        name: the worker thread's name.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        key: SwarmKey | None = None,
        observe: Callable[[Environment], None] | None = None,
        name: str | None = None,
    ) -> None:
        self._scenario = scenario
        self._key = key
        self._observe = observe
        self._outcome: concurrent.futures.Future[tuple[RunResult, Trace]] = (
            concurrent.futures.Future()
        )
        self._thread = threading.Thread(
            target=self._work, name=name or f"cas_async run {scenario.path.name}", daemon=True
        )
        self._lock = threading.Lock()  # guards the hand-over of the loop and the stop
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._stop_asked = False
        self._latest = RunProgress()
        self._started = False

    # -- from the service ------------------------------------------------------------

    def start(self) -> None:
        """Starts the run in its thread; returns at once.

        Raises:
            RobotStateError: it was started before (a run runs once).
        """
        with self._lock:
            if self._started:
                raise RobotStateError(f"{self!r} was started already: a run runs once")
            self._started = True
        self._thread.start()

    def progress(self) -> RunProgress:
        """Where the run stood at its latest snapshot; safe from any thread.

        Before the robots run: all zero (``target`` too); once it ended, ``status``
        is set and the figures are final.
        """
        return self._latest

    def stop(self) -> None:
        """Asks the run to end where it stands (status INTERRUPTED); safe from any thread.

        Returns at once: await the run for its result. Nothing happens to a run
        that has ended; a run not started yet will end as soon as it starts.
        """
        with self._lock:
            self._stop_asked = True
            loop, stop = self._loop, self._stop
        if loop is not None and stop is not None:
            with contextlib.suppress(RuntimeError):  # its loop has closed: the run ended
                loop.call_soon_threadsafe(stop.set)

    @property
    def done(self) -> bool:
        """Whether the run has ended (or failed to start)."""
        return self._outcome.done()

    async def wait(self) -> RunResult:
        """Starts the run if it was not, and returns its result once it has ended.

        The calling loop goes on meanwhile. Cancelling the caller stops the run
        (and does not wait for it).

        Raises:
            ScenarioError, ConfigurationError: the scenario could not run (the app's
                build, the transport): what ``python -m cas_async run`` would print.
        """
        if not self._started:
            self.start()
        try:
            # Shielded: a waiter that goes away must not cancel the run's own future.
            result, _ = await asyncio.shield(asyncio.wrap_future(self._outcome))
        except asyncio.CancelledError:
            self.stop()
            raise
        return result

    def __await__(self) -> Generator[Any, None, RunResult]:
        return self.wait().__await__()

    @property
    def trace(self) -> Trace:
        """Where the robots were over simulated time, once the run has ended.

        Raises:
            RobotStateError: the run has not ended yet.
        """
        if not self._outcome.done():
            raise RobotStateError(f"{self!r} has not ended: await it first")
        _, trace = self._outcome.result()
        return trace

    async def __aenter__(self) -> BackgroundRun:
        """Starts the run."""
        self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        """Stops the run if it still runs, and waits for its end (its error is not raised)."""
        self.stop()
        with contextlib.suppress(Exception):
            await asyncio.shield(asyncio.wrap_future(self._outcome))

    def __repr__(self) -> str:
        return f"BackgroundRun({str(self._scenario.path)!r})"

    # -- in the worker thread ---------------------------------------------------------

    def _work(self) -> None:
        self._outcome.set_running_or_notify_cancel()  # from now on nobody can cancel it
        try:
            outcome = run_loop(self._run(), virtual=self._scenario.run.virtual)
        except BaseException as exc:  # the service gets it where it awaits
            self._outcome.set_exception(exc)
        else:
            self._outcome.set_result(outcome)

    async def _run(self) -> tuple[RunResult, Trace]:
        stop = asyncio.Event()
        with self._lock:
            self._loop, self._stop = asyncio.get_running_loop(), stop
            if self._stop_asked:
                stop.set()
        scenario_run = ScenarioRun(self._scenario, key=self._key, stop=stop, observe=self._observe)
        async with scenario_run:
            publishing = asyncio.ensure_future(self._publish(scenario_run))
            try:
                await scenario_run.until_done()
            finally:
                publishing.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await publishing
        self._latest = scenario_run.progress()  # the end, as measured once stopped
        return scenario_run.result, scenario_run.trace

    async def _publish(self, scenario_run: ScenarioRun) -> None:
        """Takes a snapshot of the run's progress at every interval, for :meth:`progress`."""
        run = self._scenario.run
        # Loop seconds: simulated on the virtual-time loop, wall seconds otherwise.
        interval = run.trace_interval if run.virtual else run.progress_interval
        while True:
            self._latest = scenario_run.progress()  # one reference: read whole by any thread
            await asyncio.sleep(interval)
