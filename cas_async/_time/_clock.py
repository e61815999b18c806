"""Simulated time: a scaled real-time clock and a virtual-time clock.

Robotic layers express durations in *simulated seconds* and sleep them on the
robot's clock; application layers read ``clock.now()``. Two implementations:

* :class:`ScaledClock`: real time sped up by ``time_factor``; ``sleep(d)`` waits
  ``d / time_factor`` real seconds. Runs on any event loop, with real sockets.
* :class:`VirtualClock`: the event loop's own clock is virtual and jumps to the next
  timer whenever every task is idle (see :mod:`cas_async._time._virtual_loop`), so a
  simulation runs as fast as the CPU allows and a seeded run is reproducible.

This is the only module that reads time: the rest of the package asks a clock.

Timers never go off before their simulated instant: uvloop rounds every delay to
the nearest millisecond (and runs one under half a millisecond at once), so real
time deadlines are padded by that rounding. A layer woken by ``wake_after`` or a
sleep can then trust ``now()`` to have reached the instant it asked for, however
large the time factor (at factor 100, half a millisecond early is 50 ms simulated).
Virtual time needs no pad: the loop jumps to each timer's instant exactly.
"""

from __future__ import annotations

import asyncio
import os
import time
from abc import ABC, abstractmethod
from typing import Final, final

from .._errors import ConfigurationError
from ._loop_timers import timer_pad
from ._virtual_loop import VirtualTimeLoop

__all__ = ["Clock", "ScaledClock", "VirtualClock"]

_IN_PYTEST_TEST: Final = "PYTEST_CURRENT_TEST"
"""The variable pytest sets while a test runs: the error names the marker there."""


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


class Clock(ABC):
    """Simulated time for a swarm: robots of one simulation share one clock.

    The clock's origin (simulated time 0) is fixed the first time it is started or
    read, normally when the first robot starts.
    """

    is_virtual: bool = False
    """True when time is virtual (only in-process transports can be used)."""

    def __init__(self) -> None:
        self._origin: float | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pad = 0.0  # loop seconds added to every deadline: see _loop_timers
        self._next_ids: dict[int, int] = {}  # robot -> the first id it has not used

    @property
    @abstractmethod
    def time_factor(self) -> float:
        """Simulated seconds per real second (``inf`` for virtual time)."""

    @abstractmethod
    def _loop_time_per_sim_second(self) -> float:
        """How many loop-clock seconds one simulated second lasts."""

    def check_loop(self, loop: asyncio.AbstractEventLoop) -> None:  # noqa: B027 - optional hook
        """Raises ``ConfigurationError`` when this clock cannot run on ``loop``."""

    def start(self) -> None:
        """Fixes simulated time 0 at the current instant, if not fixed already.

        Raises:
            ConfigurationError: the clock already runs on another event loop (its
                time 0 and deadlines belong to that loop's clock).
        """
        if self._loop is not None and self._loop is not asyncio.get_running_loop():
            raise ConfigurationError(
                f"this {type(self).__name__} was started on another event loop; "
                "create a new clock for each run"
            )
        if self._origin is None:
            loop = asyncio.get_running_loop()
            self.check_loop(loop)
            self._loop = loop  # kept: get_running_loop() costs a getpid() call on 3.11
            self._pad = self._timer_pad(loop)
            self._origin = loop.time()

    def _timer_pad(self, loop: asyncio.AbstractEventLoop) -> float:
        """Loop seconds added to every deadline so that no timer goes off before it."""
        return timer_pad(loop)

    def now(self) -> float:
        """Simulated seconds since the clock started."""
        loop, origin = self._loop, self._origin
        if loop is None or origin is None:  # not started: starts on the running loop
            self.start()
            loop, origin = self._loop, self._origin
            assert loop is not None
            assert origin is not None
        return (loop.time() - origin) / self._loop_time_per_sim_second()

    async def sleep(self, seconds: float) -> None:
        """Waits ``seconds`` of simulated time (a non-positive value just yields).

        In a loop of steps, prefer :meth:`sleep_until` of ``start + n * step``: a
        relative sleep starts from whenever the previous step ended, so the time
        the steps take (and every timer's lateness) adds up.
        """
        if seconds > 0:
            _, pad = self._loop_and_pad()
            await asyncio.sleep(seconds * self._loop_time_per_sim_second() + pad)
        else:
            await asyncio.sleep(0)

    async def sleep_until(self, deadline: float) -> None:
        """Waits until simulated time ``deadline`` (a past one just yields).

        The timer is armed for the loop time of ``deadline`` itself, not for a
        delay from now: a sequence of sleeps to ``start + n * step`` lands exactly
        on each instant (in virtual time) or as close as the loop's timers allow
        (in real time), however long each step's work took and however late each
        wake-up was. Never returns before ``now() >= deadline``.
        """
        loop = self._loop or asyncio.get_running_loop()
        when = self.loop_time_at(deadline)
        if when <= loop.time():
            await asyncio.sleep(0)
            return
        future = loop.create_future()
        handle = loop.call_at(when + self._pad, _wake, future)
        try:
            await future
        finally:
            handle.cancel()  # cancelled while waiting: the timer must not outlive us

    def loop_time_at(self, t: float) -> float:
        """The event-loop time of simulated instant ``t`` (the inverse of :meth:`at_loop_time`)."""
        if self._origin is None:
            self.start()
        assert self._origin is not None
        return self._origin + t * self._loop_time_per_sim_second()

    def loop_deadline(self, seconds: float) -> float:
        """The event-loop time to arm a timer ``seconds`` of simulated time from now.

        For code that schedules many deadlines on the loop itself (request
        timeouts, ``wake_after``). Padded by the loop's timer rounding, so that a
        timer armed for it finds ``now()`` at or past the instant.
        """
        loop = self._loop
        if loop is None:  # not started: the running loop, and its pad
            loop, pad = self._loop_and_pad()
            return loop.time() + max(0.0, seconds) * self._loop_time_per_sim_second() + pad
        if not seconds > 0.0:  # negative, or NaN: now
            seconds = 0.0
        return loop.time() + seconds * self._loop_time_per_sim_second() + self._pad

    def loop_deadline_at(self, t: float) -> float:
        """The event-loop time to arm a timer for simulated instant ``t``.

        Padded like :meth:`loop_deadline`: a timer armed for it finds ``now()`` at
        or past ``t`` (up to the rounding of one subtraction; see
        :class:`~cas_async._core._timers.Timers`, which checks).
        """
        _, pad = self._loop_and_pad()
        return self.loop_time_at(t) + pad

    def _loop_and_pad(self) -> tuple[asyncio.AbstractEventLoop, float]:
        """The loop, and its timer pad, also before the clock is started."""
        loop = self._loop
        if loop is None:
            loop = asyncio.get_running_loop()
            return loop, self._timer_pad(loop)
        return loop, self._pad

    def at_loop_time(self, loop_time: float) -> float:
        """The simulated time at event-loop time ``loop_time`` (for times the loop recorded)."""
        if self._origin is None:
            self.start()
        assert self._origin is not None
        return (loop_time - self._origin) / self._loop_time_per_sim_second()

    def id_time(self) -> int:
        """Now, in message-id units: microseconds of the wall clock.

        Message ids count from it (see :meth:`message_id_base`), and a receiver
        refuses an id far beyond its own ``id_time()`` as forged.
        """
        return time.time_ns() // 1000

    def message_id_base(self, robot_id: int) -> int:
        """The first message id of robot ``robot_id`` starting now: above any it used before.

        Message ids only grow, also across restarts of a robot, so receivers can
        tell a repeated message from a new one. The base is :meth:`id_time`, or,
        for a robot that ran before on this clock, the id after its last one
        (:meth:`ids_used`), whichever is larger: a restart at the same instant, or
        after a burst of more than one message per microsecond, still goes on
        above its previous life. A robot that ran in another process starts above
        its previous ids as long as it sent fewer than a million messages a second.
        """
        return max(self.id_time(), self._next_ids.get(robot_id, 0))

    def ids_used(self, robot_id: int, next_id: int) -> None:
        """Robot ``robot_id`` stopped; ``next_id`` is the first id it did not use."""
        if next_id > self._next_ids.get(robot_id, 0):
            self._next_ids[robot_id] = next_id

    def loop_seconds(self, seconds: float) -> float:
        """How many event-loop seconds ``seconds`` of simulated time last."""
        return seconds * self._loop_time_per_sim_second()

    def timeout(self, seconds: float | None) -> asyncio.Timeout:
        """An ``async with`` block that raises ``TimeoutError`` after ``seconds`` simulated."""
        if seconds is None:
            return asyncio.timeout(None)
        return asyncio.timeout_at(self.loop_deadline(seconds))


@final
class ScaledClock(Clock):
    """Real time sped up: ``sleep(d)`` lasts ``d / time_factor`` real seconds.

    Args:
        time_factor: simulated seconds per real second; 1.0 is real time.
    """

    def __init__(self, time_factor: float = 1.0) -> None:
        super().__init__()
        if not time_factor > 0 or time_factor == float("inf"):
            raise ConfigurationError(
                f"time_factor must be a positive finite number, got {time_factor!r}"
                " (use VirtualClock for as-fast-as-possible runs)"
            )
        self._factor = float(time_factor)
        self._scale = 1.0 / self._factor

    @property
    def time_factor(self) -> float:
        """Simulated seconds per real second."""
        return self._factor

    def _loop_time_per_sim_second(self) -> float:
        return self._scale

    def start_at_wall(self, epoch: float) -> None:
        """Fixes simulated time 0 at wall-clock instant ``epoch`` (``time.time()`` seconds).

        How clocks in several processes, or hosts with synchronised clocks, keep one
        simulated time: each is told the same instant. Call it on the loop the robots
        run on, before they start.

        Raises:
            ConfigurationError: the clock has started already.
        """
        if self._origin is not None:
            raise ConfigurationError("this ScaledClock has started already: align it before")
        self.start()
        loop, _ = self._loop_and_pad()
        self._origin = loop.time() + (epoch - time.time())

    def __repr__(self) -> str:
        return f"ScaledClock(time_factor={self._factor:g})"


@final
class VirtualClock(Clock):
    """Virtual time: needs the loop of :class:`~cas_async._time._virtual_loop.VirtualTimeLoop`.

    Start one with ``cas_async.run(main(), virtual=True)``. Simulated seconds are
    the loop's seconds, so ``asyncio.sleep`` and timeouts follow virtual time too.
    """

    is_virtual = True

    @property
    def time_factor(self) -> float:
        """Always ``inf``: the loop jumps over idle time."""
        return float("inf")

    def _loop_time_per_sim_second(self) -> float:
        return 1.0

    def _timer_pad(self, loop: asyncio.AbstractEventLoop) -> float:
        """None: the virtual loop runs each timer at its instant exactly."""
        return 0.0

    def id_time(self) -> int:
        """Virtual microseconds since the loop began, plus one: reproducible, and growing."""
        loop = self._loop or asyncio.get_running_loop()
        return int(loop.time() * 1_000_000) + 1

    def check_loop(self, loop: asyncio.AbstractEventLoop) -> None:
        """Refuses loops whose clock is real."""
        if not isinstance(loop, VirtualTimeLoop):
            running = type(loop).__name__
            if _IN_PYTEST_TEST in os.environ:  # pytest sets it while a test runs
                raise ConfigurationError(
                    "VirtualClock needs the virtual-time event loop: mark the test "
                    "@pytest.mark.cas_virtual (the cas_async pytest plugin then runs it on "
                    f"that loop), or use ScaledClock; this test runs on {running}"
                )
            raise ConfigurationError(
                f"VirtualClock needs the virtual-time event loop, but this loop is "
                f"{running}: run with cas_async.run(main(), virtual=True) "
                "(in a pytest test: mark it @pytest.mark.cas_virtual) or use ScaledClock"
            )

    def __repr__(self) -> str:
        return "VirtualClock()"
