"""A run with a network latency, on virtual time, in one process: its windows and its mirror.

What :class:`~cas_async.scenario.ScenarioRun` adds to a run when the scenario sets
a latency (``[network] latency``) and its mission's objective reads only the
Environment (it is ``distributable``): the robots' time moves in windows (see
:mod:`._windows`), and the run observes a mirror of the robots' Environment fed
window by window in a fixed order (see :mod:`._observer`): the very way a run
across processes observes its workers' robots, so that both measure the same.
"""

from __future__ import annotations

import asyncio
import math
from asyncio import FIRST_COMPLETED
from collections.abc import Awaitable, Callable
from typing import Any, final

from ..._errors import ConfigurationError
from ..._time._clock import Clock
from ..._time._virtual_loop import VirtualTimeLoop
from ...sim._environment import Environment
from .._processes._observer import Observer, Recorder, mirror_of
from .._processes._windows import Steps, Windows
from .._spec._loader import Scenario
from ..output._results import RunStatus
from ._sampled import first_ended

__all__ = ["WindowedRun"]


@final
class WindowedRun:
    """The windows of a run in one process, and what it observes (see the module docs).

    Args:
        scenario: the run's scenario (its latency, ``max_time`` and sample interval).
        environment: the robots' Environment, once the application placed them.
        sample: awaited at each sample instant (the mirror is there).
        done: whether the mission is complete.
    """

    def __init__(
        self,
        scenario: Scenario,
        environment: Environment,
        clock: Clock,
        sample: Callable[[float], Awaitable[None]],
        done: Callable[[], bool],
    ) -> None:
        self.latency = scenario.network.latency
        self._clock = clock
        self._max_time = scenario.run.max_time
        self.mirror = mirror_of(environment)
        """What the run observes: every robot, every motion and item event, in order."""
        self._recorder = Recorder(environment, environment.robot_ids, keep=True)
        self._observer = Observer(
            self.mirror, scenario.run.trace_interval, sample, done, self._recorder.kept
        )
        self._done = done
        self.timed_out = False
        """Whether the run reached ``max_time`` (or nothing could happen any more)."""
        self.ended = asyncio.Event()
        """Set when the windows end by themselves: timed out, or closing one failed."""
        self._steps = Steps(scenario.credit, self.latency, self._max_time)
        self._ends_at = math.inf  # once decided: the run ends there
        self._stopped_at: float | None = None  # when every robot had stopped, if they have
        self.verdict: RunStatus | None = None
        """Completed or stopped, once a window decided it (see :meth:`_close`)."""
        self._windows: Windows | None = None
        self._loop: VirtualTimeLoop | None = None

    @property
    def observed_until(self) -> float:
        """The instant up to which the run was observed (the last window's end)."""
        return self._observer.until

    @property
    def rounds(self) -> int:
        """Windows closed so far."""
        return 0 if self._windows is None else self._windows.rounds

    @property
    def failure(self) -> BaseException | None:
        """What closing a window raised (an audit that failed, say), if anything."""
        return None if self._windows is None else self._windows.failure

    async def until_done(
        self, running: Awaitable[None], complete: asyncio.Event, stop: asyncio.Event
    ) -> tuple[RunStatus, BaseException | None]:
        """Waits for the end of the run: which it is, and the failure of a failed one.

        Every robot stopping ends nothing by itself: the window in which they did
        decides, once it has observed everything up to that instant (the objective
        may have been met by then: completed, else stopped), as a run across
        processes does.
        """
        swarm = asyncio.ensure_future(running)
        waits = {
            "windows": asyncio.ensure_future(self.ended.wait()),
            "stop": asyncio.ensure_future(stop.wait()),
        }
        try:
            waiting: list[asyncio.Future[Any]] = [swarm, *waits.values()]
            done, _ = await asyncio.wait(waiting, return_when=FIRST_COMPLETED)
            if swarm in done and swarm.exception() is None and not self.ended.is_set():
                self._stopped_at = self._clock.now()  # the windows decide (see _close)
                done = await first_ended(waits.values())
        finally:
            swarm.cancel()
            for task in waits.values():
                task.cancel()
        if complete.is_set():
            return RunStatus.COMPLETED, None
        if swarm.done() and not swarm.cancelled() and swarm.exception() is not None:
            return RunStatus.FAILED, swarm.exception()
        if self.verdict is not None:
            return self.verdict, None
        if self.failure is not None:
            return RunStatus.FAILED, self.failure
        if waits["stop"] in done:
            return RunStatus.INTERRUPTED, None
        return RunStatus.TIMED_OUT, None

    def start(self) -> None:
        """Time moves in windows from now on (call before the robots start).

        Raises:
            ConfigurationError: the loop is not on virtual time.
        """
        loop = asyncio.get_running_loop()
        if not isinstance(loop, VirtualTimeLoop):
            raise ConfigurationError(
                "a run with a network latency on virtual time needs the virtual-time loop: "
                "cas_async.run(..., virtual=True)"
            )
        self._loop = loop
        first = self._clock.loop_time_at(self._steps.first_end)
        self._windows = Windows(loop, first, self._close, self.ended.set, quick=self._quick)
        loop.run_windows(self._windows)

    def observe_now(self) -> None:
        """Observes what the robots did since the last window, up to now, without sampling.

        For a run that ends between two windows (interrupted, or failed): it is
        measured where it stands, as a run without windows is.
        """
        if self._loop is not None:
            self._observer.apply([self._recorder.take()], until=self._clock.now())

    def stop(self) -> None:
        """The run ended: time moves freely again (the robots are stopped)."""
        if self._windows is not None:
            self._windows.stop()
        if self._loop is not None:
            self._loop.run_windows(None)

    def _quick(self, end: float, next_event: float) -> float | None:
        """Closes the window at once if it has no sample and does not end the run."""
        observer, clock = self._observer, self._clock
        end_t = clock.at_loop_time(end)
        following = clock.at_loop_time(next_event)
        if (
            self.verdict is not None
            or self._stopped_at is not None
            or observer.next_sample < end_t
            or following >= self._max_time
            or math.isinf(following)
        ):
            return None
        observer.apply([self._recorder.take()], until=end_t)
        if self._done():  # complete in this window: the run ends at the next step's end
            self._decide(RunStatus.COMPLETED)
        self._steps.ended(end_t)
        return self._next_end(following)

    async def _close(self, end: float, next_event: float) -> float | None:
        """Observes the window that ends at ``end``; the end of the next one, if any.

        Windows end at every step too (see :class:`~.._processes._windows.Steps`).
        Once a window decided the run in step ``c`` (completed, or every robot
        stopped before the objective was met), the robots run every event before
        the end of step ``c + 1``, unobserved, and no later one, as a run across
        processes does (its workers run ahead of the world's observation): both
        measure the same. A window in which every robot stopped is observed up to
        that instant only.
        """
        clock, observer = self._clock, self._observer
        end_t, following = clock.at_loop_time(end), clock.at_loop_time(next_event)
        if self.verdict is None:
            records = self._recorder.take()
            stopped_at = self._stopped_at
            if stopped_at is not None:
                await observer.window(stopped_at, [records.split(stopped_at)[0]])
                self._decide(RunStatus.COMPLETED if self._done() else RunStatus.STOPPED)
            else:
                await observer.window(end_t, [records])
                if self._done():
                    self._decide(RunStatus.COMPLETED)
                elif following >= self._max_time or math.isinf(following):
                    # Nothing happens before max_time any more: sample up to it, and time out.
                    await observer.sample_until(self._max_time, inclusive=False)
                    self.timed_out = True
                    self.ended.set()
                    return None
        self._steps.ended(end_t)
        if self.verdict is not None and (
            end_t >= self._ends_at or following >= min(self._ends_at, self._max_time)
        ):
            self.ended.set()  # every event before the end ran: none after it
            return None
        return self._next_end(following)

    def _decide(self, verdict: RunStatus) -> None:
        """The run is decided in the step under way: it ends at the next one's end."""
        self.verdict = verdict
        steps = self._steps
        self._ends_at = steps.end_of_run(steps.index * steps.credit)

    def _next_end(self, following: float) -> float:
        """The next window's end (loop time), its first event at ``following`` (simulated)."""
        return self._clock.loop_time_at(min(self._steps.next_end(following), self._ends_at))
