"""Simulated time in lookahead windows: the conservative parallel simulation of a run.

With a network latency ``L`` nothing a robot does at ``t`` reaches another robot
before ``t + L`` (see :mod:`cas_async._time._deliveries`). So every event before
``T + L``, where ``T`` is the earliest event to come of the whole run, can run
without waiting for anyone: that is a *window*. When every event before the
window's end has run, the window closes: the run observes what happened in it
(:mod:`._observer`), the processes of a run across processes exchange what their
robots sent each other, and the next window opens at the next event of the whole
run, ``L`` long. This is the lookahead of conservative parallel discrete-event
simulation (YAWNS; ns-3's distributed simulator; HLA's time management): one
synchronization per window instead of one per instant.

A window's events all run before it closes, and its end depends only on the
run's events, which are the same however the robots are spread: a run stops at
the end of the step (:class:`Steps`) after the one in which its mission was
complete, in one process as in many, and so measures the same.

Across processes each worker's windows are its own: a window ends where the
workers it depends on promised their next effect (see :mod:`._control`), so a
worker whose robots are far from the others' runs ahead of them.

:class:`Windows` drives a :class:`~cas_async._time._virtual_loop.VirtualTimeLoop`
(through :meth:`~cas_async._time._virtual_loop.VirtualTimeLoop.run_windows`): the loop
asks it when its next event is at or after the window's end, and a window
closes on a task of its own, so that closing may await (a paced live view, the
other processes' news).
"""

from __future__ import annotations

import asyncio
import math
import selectors
from collections.abc import Awaitable, Callable
from typing import Final

__all__ = ["Held", "Steps", "Windows"]

Closer = Callable[[float, float], Awaitable[float | None]]
"""``close(end, next_event)``: closes the window ending at ``end``; the next event of
this process is at ``next_event``. Returns the next window's end, or ``None`` when
the run is over."""
QuickCloser = Callable[[float, float], float | None]
"""``quick(end, next_event)``: closes the window at once when nothing in it needs to
await (most windows of a run in one process); returns the next window's end, or
``None`` when it cannot (then ``close`` does it)."""

_SELECT: Final = 0.05
"""Wall seconds the idle loop waits for other threads while a window closes."""


class Windows:
    """The windows of one loop (see the module docs).

    Args:
        loop: the loop whose time moves in windows.
        first_end: where the first window ends (the start plus the latency).
        close: closes a window (see :data:`Closer`).
        failed: called when closing a window raised (see :attr:`failure`).
        idle: called whenever the closing waited ~50 ms for other threads in vain,
            so that whoever waits can look at the wall clock.
        quick: closes a window at once where it can (see :data:`QuickCloser`).
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        first_end: float,
        close: Closer,
        failed: Callable[[], None] = lambda: None,
        idle: Callable[[], None] = lambda: None,
        quick: QuickCloser | None = None,
    ) -> None:
        self._loop = loop
        self._idle = idle
        self._quick = quick
        self._end = first_end
        self._close = close
        self._failed = failed
        self._closing: asyncio.Task[None] | None = None
        self.rounds = 0
        """Windows closed so far."""
        self.over = False
        """The run is over: time no longer moves in windows."""
        self.failure: BaseException | None = None
        """What closing a window raised, if it failed (the run then fails)."""

    @property
    def end(self) -> float:
        """The loop time the open window ends at (``inf`` once the run is over)."""
        return self._end

    def closed(
        self, next_event: float, selector: selectors.BaseSelector
    ) -> list[tuple[selectors.SelectorKey, int]]:
        """The loop is idle and its next event is at or after :attr:`end`: the window closes."""
        if self.over:  # nothing is scheduled at all (the end is inf): as a loop without windows
            return selector.select(None)
        if self._closing is None:
            following = None if self._quick is None else self._quick(self._end, next_event)
            if following is not None:
                self.rounds += 1
                self._end = following
                return []  # the loop looks again: runs on, or closes the next window
            self._closing = self._loop.create_task(self._run_close(self._end, next_event))
            return []
        # The closing waits for another thread (another process's news): wait with it.
        ready = selector.select(_SELECT)
        if not ready:
            self._idle()
        return ready

    async def _run_close(self, end: float, next_event: float) -> None:
        try:
            following = await self._close(end, next_event)
        except BaseException as exc:
            self.failure = exc
            self.stop()
            self._failed()
            if not isinstance(exc, Exception):
                raise
            return
        finally:
            self._closing = None
        self.rounds += 1
        if following is None:
            self.stop()
        elif not self.over:
            self._end = following

    def clip(self, end: float) -> None:
        """Ends the open window at ``end`` instead, if that is sooner (a pause coming there).

        A window may end sooner than the lookahead allows: it then holds fewer events,
        and what the run measures does not change (it does not depend on where
        windows end). Nothing changes while a window is closing.
        """
        if self._closing is None and not self.over:
            self._end = min(self._end, end)

    def stop(self) -> None:
        """The run is over: time moves freely from now on (the robots are being stopped)."""
        self.over = True
        self._end = math.inf


class Steps:
    """Where the windows of a run end: a latency after their first event, or at a step.

    Windows of a run observed window by window (one process with a latency, or a
    world and its workers) also end at every *step*, each ``credit`` (``run.credit``)
    simulated seconds, and at ``max_time``. Steps are counted, never added up, so
    every process that ends its windows alike counts the same steps at the same
    instants: the world lets its workers run a step past what it observed
    (:attr:`index` + 1), an interaction range turns its epochs every ``epoch``
    steps, and a run decided in step ``c`` ends at the end of step ``c + 1``
    (:meth:`end_of_run`): a credit or two past it, in one process as in many.

    Args:
        credit: the length of a step, simulated seconds.
        latency: the run's latency: a window ends this long after its first event.
        max_time: no window ends after it.
        epoch: steps per epoch of an interaction range (``0``: no epochs).
    """

    def __init__(self, credit: float, latency: float, max_time: float, epoch: int = 0) -> None:
        self.credit = credit
        self.latency = latency
        self.max_time = max_time
        self.epoch = epoch
        self.index = 0
        """Steps ended so far: the windows under way end by ``(index + 1) * credit``."""

    @property
    def first_end(self) -> float:
        """Where the first window ends (it starts at 0)."""
        return self.next_end(0.0)

    def next_end(self, following: float) -> float:
        """Where the next window ends: ``following`` is its first event."""
        return min(following + self.latency, (self.index + 1) * self.credit, self.max_time)

    def ended(self, end: float) -> bool:
        """A window ended at ``end``; whether that was the end of a step (then counted)."""
        if end == (self.index + 1) * self.credit:
            self.index += 1
            return True
        return False

    def epoch_at(self, t: float) -> int | None:
        """The epoch that starts at instant ``t`` (a window's end), or ``None`` (see ``_halo``).

        Epoch ``e`` starts at the end of step ``e * epoch``; epoch 0 at the start.
        """
        if self.epoch == 0:
            return None
        step = self.step_of(t)
        if step > 0 and step % self.epoch == 0 and step * self.credit == t:
            return step // self.epoch
        return None

    def next_epoch(self, end: float) -> float:
        """The first epoch start at or after ``end``, a window's end (``inf``: no epochs)."""
        if self.epoch == 0:
            return math.inf
        if self.epoch_at(end) is not None:
            return end
        return (self.index // self.epoch + 1) * self.epoch * self.credit

    def step_of(self, t: float) -> int:
        """The step instant ``t`` falls in: ``c`` with ``c * credit <= t < (c + 1) * credit``.

        Exact at the steps' own instants (``c * credit``, as windows end there), whatever
        the rounding of ``t / credit``.
        """
        credit = self.credit
        step = math.floor(t / credit)
        while (step + 1) * credit <= t:
            step += 1
        while step > 0 and step * credit > t:
            step -= 1
        return step

    def end_of_run(self, decided_at: float) -> float:
        """Where a run decided at ``decided_at`` ends: the end of the step after its step."""
        return (self.step_of(decided_at) + 2) * self.credit


class Held:
    """Windows that never open: the loop's time stands still (a world process waits on others).

    While a world waits for its workers, nothing on its own loop may make time
    jump (a stray timer would): the idle loop only waits for other threads, and
    calls ``idle`` every time it waited for nothing (about every 50 ms), so that
    whoever waits can look at the wall clock.

    Args:
        idle: called when a wait for other threads ended with nothing.
    """

    end = -math.inf

    def __init__(self, idle: Callable[[], None] = lambda: None) -> None:
        self._idle = idle

    def clip(self, end: float) -> None:
        """Nothing to clip: no window is open."""

    def closed(
        self, next_event: float, selector: selectors.BaseSelector
    ) -> list[tuple[selectors.SelectorKey, int]]:
        """Waits for other threads (the workers' news), never moving time."""
        ready = selector.select(_SELECT)
        if not ready:
            self._idle()
        return ready
