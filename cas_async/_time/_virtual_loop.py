"""An asyncio event loop whose clock is virtual and jumps over idle time.

asyncio asks its selector to wait ``timeout`` seconds when no callback is ready:
exactly the moment every task is idle until the next timer. This loop's selector
polls real I/O without waiting and, when nothing is ready, advances the virtual
clock by ``timeout`` instead of sleeping. Timers then fire in deadline order at
their exact virtual instants (those of one instant in the order they were armed),
so runs are as fast as the CPU allows and, with the same inputs, identical.

The selector polls real I/O once every :data:`POLL_EVERY` passes only (a system
call each time, a few percent of a large simulation), and always before it really
waits. What other threads hand over with ``call_soon_threadsafe`` runs on the next
pass all the same (asyncio queues it itself); a signal, or a socket's data, waits
for the next poll: a few passes, in which virtual time may move on, as it may while
the data is on its way.

Real sockets do not run on virtual time (their data would arrive "late" in virtual
terms, or the loop would jump past it), so robots refuse UDP with a virtual clock.
When nothing at all is scheduled the selector really blocks, so work handed to
threads (``call_soon_threadsafe``) still wakes the loop.

uvloop's timers live in libuv and ignore an overridden ``time()``, so virtual time
always uses this stdlib-based loop.
"""

from __future__ import annotations

import asyncio
import contextvars
import heapq
import math
import selectors
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Final, Protocol, TypeVarTuple, Unpack

if TYPE_CHECKING:
    from ._deliveries import Deliveries


class Windows(Protocol):
    """How a loop's time moves in windows: what :meth:`VirtualTimeLoop.run_windows` takes."""

    @property
    def end(self) -> float:
        """The loop time the current window ends at (exclusive)."""

    def closed(
        self, next_event: float, selector: selectors.BaseSelector
    ) -> list[tuple[selectors.SelectorKey, int]]:
        """Every event before :attr:`end` has run; the next is at ``next_event``.

        Called by the idle loop instead of jumping: it may open the next window
        (move :attr:`end`) and return ``[]``, or wait on the real ``selector``
        for other threads (another process's news) and return what it found.
        """

    def clip(self, end: float) -> None:
        """Ends the current window at ``end`` if that is sooner (a pause comes there)."""


__all__ = ["POLL_EVERY", "VirtualTimeLoop", "Windows"]

POLL_EVERY: Final = 16
"""Passes of the loop between two polls of real I/O (see the module docs)."""


class _JumpingSelector(selectors.BaseSelector):
    """Delegates to a real selector, but turns idle waits into clock jumps."""

    def __init__(self, inner: selectors.BaseSelector, loop: VirtualTimeLoop) -> None:
        self._inner = inner
        self._loop = loop
        self._unpolled = 0  # passes since the real selector was last polled

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._inner.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.modify(fileobj, events, data)

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        self._unpolled += 1
        if self._unpolled >= POLL_EVERY:
            self._unpolled = 0
            ready = self._inner.select(0)
            if ready:
                self._loop.busy_pass()
                return ready
        if timeout is not None and timeout <= 0:
            self._loop.busy_pass()
            return []
        # Idle: nothing to run before the next timer or I/O.
        if self._loop.wake_idle_waiters():  # they look first; time moves after
            return []
        return self._loop.when_idle(timeout, self._inner)

    def close(self) -> None:
        self._inner.close()

    def get_key(self, fileobj: Any) -> selectors.SelectorKey:
        return self._inner.get_key(fileobj)

    def get_map(self) -> Any:
        return self._inner.get_map()


_Ts = TypeVarTuple("_Ts")


class _Timer(asyncio.TimerHandle):
    """A timer that runs after every timer armed before it for the same instant.

    asyncio orders its timers by instant alone, in a heap: those of one instant
    then run in an order that depends on every other timer in the heap. A robot's
    timers of one instant would run in another order when its process runs other
    robots (a run across processes), and what follows from them too.
    """

    __slots__ = ("_at", "_order")

    def __init__(
        self,
        when: float,
        callback: Callable[..., object],
        args: Sequence[Any],
        loop: asyncio.AbstractEventLoop,
        context: contextvars.Context | None,
        order: int,
    ) -> None:
        super().__init__(when, callback, args, loop, context)
        self._at = when
        self._order = order

    def __lt__(self, other: _Timer) -> bool:  # type: ignore[override]
        # The heap's one comparison, so written for speed: every timer of this loop
        # is a _Timer (call_at makes them all).
        at, other_at = self._at, other._at
        return at < other_at or (at == other_at and self._order < other._order)


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """A selector event loop on virtual time, starting at 0.0."""

    def __init__(self) -> None:
        self._virtual_now = 0.0
        self._idle_waiters: list[asyncio.Future[None]] = []
        self._busy_passes = 0
        self._deliveries: Deliveries | None = None
        self._windows: Windows | None = None
        self._timers_armed = 0
        super().__init__(_JumpingSelector(selectors.DefaultSelector(), self))

    def call_at(
        self,
        when: float,
        callback: Callable[[Unpack[_Ts]], object],
        *args: *_Ts,
        context: contextvars.Context | None = None,
    ) -> asyncio.TimerHandle:
        """As asyncio's, but timers of one instant run in the order they were armed."""
        if when is None:
            raise TypeError("when cannot be None")
        self._check_closed()  # type: ignore[attr-defined]
        if self._debug:  # type: ignore[attr-defined]
            self._check_thread()  # type: ignore[attr-defined]
            self._check_callback(callback, "call_at")  # type: ignore[attr-defined]
        self._timers_armed += 1
        timer = _Timer(when, callback, args, self, context, self._timers_armed)
        heapq.heappush(self._scheduled, timer)  # type: ignore[attr-defined]
        timer._scheduled = True  # type: ignore[attr-defined]
        return timer

    # asyncio runs, in each pass, every timer due before ``time() + _clock_resolution``
    # (the monotonic clock's resolution, a nanosecond, for real time). Virtual time
    # is exact: a timer runs once time has reached its instant, not a fraction of a
    # nanosecond before, at whatever event came just before it (the events before it
    # depend on which robots share the loop: identical runs across processes rely on
    # this). The resolution is the spacing of floats at now, so that
    # ``now + resolution`` is the next float and "due before it" means "due by now".
    @property
    def _clock_resolution(self) -> float:
        return math.ulp(self._virtual_now)

    @_clock_resolution.setter
    def _clock_resolution(self, value: float) -> None:
        """Ignored: the base loop sets the monotonic clock's (see the getter)."""

    def host(self, deliveries: Deliveries) -> None:
        """Runs ``deliveries``' actions at their instants, before the timers of that instant."""
        self._deliveries = deliveries

    IDLE_PATIENCE: Final = 100_000
    """Busy passes after which :meth:`idle`'s futures fail: a task that never waits."""

    def idle(self) -> asyncio.Future[None]:
        """A future done once the loop is idle: every task waits for a timer, I/O or a thread.

        Nothing is ready to run and no timer is due: what happens next needs time
        to pass. The future is done before time moves on (a test can look at what
        everything did at this instant). It fails with :class:`RuntimeError` when
        the loop stays busy for :attr:`IDLE_PATIENCE` passes.
        """
        if not self._idle_waiters:
            self._busy_passes = 0
        future = self.create_future()
        self._idle_waiters.append(future)
        return future

    def busy_pass(self) -> None:
        """The selector saw work to do (called each busy pass); fails idle waiters past patience."""
        if not self._idle_waiters:
            return
        self._busy_passes += 1
        if self._busy_passes >= self.IDLE_PATIENCE:
            waiters, self._idle_waiters = self._idle_waiters, []
            for future in waiters:
                if not future.done():
                    future.set_exception(
                        RuntimeError(
                            f"the loop is still busy after {self.IDLE_PATIENCE} passes: "
                            "a task never waits"
                        )
                    )

    def wake_idle_waiters(self) -> bool:
        """Completes the futures of :meth:`idle` (the loop is idle); whether there were any."""
        if not self._idle_waiters:
            return False
        waiters = [future for future in self._idle_waiters if not future.done()]
        self._idle_waiters.clear()
        for future in waiters:
            future.set_result(None)
        return bool(waiters)

    def when_idle(
        self, timeout: float | None, selector: selectors.BaseSelector
    ) -> list[tuple[selectors.SelectorKey, int]]:
        """What the idle loop does: jumps to its next event, or waits for a thread.

        ``timeout`` is the time to the next timer (``None``: no timer); the next
        event is that timer or the next of the loop's deliveries (see :meth:`host`),
        whichever comes first. With windows (see :meth:`run_windows`), an event at
        or after the window's end closes the window first. ``selector`` is the real
        one, to wait on for other threads.
        """
        scheduled: list[asyncio.TimerHandle] = self._scheduled  # type: ignore[attr-defined]
        # The next timer's own instant (asyncio dropped cancelled ones from the head of
        # its heap before it computed ``timeout``): ``now + timeout`` may miss it by a
        # rounding, and a delivery of the timer's very instant must go first.
        timer = scheduled[0].when() if timeout is not None and scheduled else math.inf
        deliveries = self._deliveries
        due = math.inf if deliveries is None else deliveries.next_at()
        windows = self._windows
        if windows is not None and min(timer, due) >= windows.end:
            return windows.closed(min(timer, due), selector)
        if due <= timer and due != math.inf:
            assert deliveries is not None
            self._virtual_now = max(self._virtual_now, due)
            if due < timer:
                # No timer of this instant: they run now, and what they wake runs in
                # this very pass, as it would have in the next (one pass less each).
                deliveries.run_due(self._virtual_now)
            else:  # the first callback of the pass: before the timers of the same instant
                self.call_soon(deliveries.run_due, self._virtual_now)
            return []
        if timeout is None:  # no timer at all: only another thread can wake us
            return selector.select(None)
        # To the timer's own instant, not ``now + timeout``: that may miss it by a
        # rounding, and the time the timer reads would then depend on the events
        # before it (on which robots share the loop).
        self._virtual_now = max(self._virtual_now, timer)
        return []

    def run_windows(self, windows: Windows | None) -> None:
        """Moves time in ``windows`` from now on (``None``: freely again).

        Every event before ``windows.end`` runs as usual; when the next event is at
        or after it, the loop calls ``windows.closed`` instead of jumping there
        (see :mod:`cas_async.scenario._processes._windows`).
        """
        self._windows = windows

    def time(self) -> float:
        """The virtual time, in seconds."""
        return self._virtual_now

    def next_deadline(self) -> float:
        """The instant of the loop's next event: a timer or a delivery (``inf``: none).

        Cancelled timers still at the head of the heap count (asyncio drops them
        before it selects; call it from :meth:`when_idle`, where it has).
        """
        scheduled: list[asyncio.TimerHandle] = self._scheduled  # type: ignore[attr-defined]
        timer = scheduled[0].when() if scheduled else math.inf
        deliveries = self._deliveries
        return min(timer, math.inf if deliveries is None else deliveries.next_at())

    def timer_deadlines(self) -> list[float]:
        """The virtual instants of the timers still to go off, earliest first."""
        # The base loop's heap of timers (typeshed does not declare it); cancelled
        # handles stay in it until the loop cleans up, so they are skipped here.
        scheduled: list[asyncio.TimerHandle] = self._scheduled  # type: ignore[attr-defined]
        return sorted(handle.when() for handle in scheduled if not handle.cancelled())

    def advance(self, seconds: float) -> None:
        """Moves virtual time forward; it never goes back.

        Raises:
            ValueError: ``seconds`` is negative.
        """
        if seconds < 0:
            raise ValueError(f"virtual time cannot go backwards (advance by {seconds})")
        self._virtual_now += seconds
