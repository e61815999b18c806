"""An asyncio event loop whose clock is virtual and jumps over idle time.

asyncio asks its selector to wait ``timeout`` seconds when no callback is ready:
exactly the moment every task is idle until the next timer. This loop's selector
polls real I/O without waiting and, when nothing is ready, advances the virtual
clock by ``timeout`` instead of sleeping. Timers then fire in deadline order at
their exact virtual instants, so runs are as fast as the CPU allows and, with the
same inputs, identical.

Real sockets do not run on virtual time (their data would arrive "late" in virtual
terms, or the loop would jump past it), so robots refuse UDP with a virtual clock.
When nothing at all is scheduled the selector really blocks, so work handed to
threads (``call_soon_threadsafe``) still wakes the loop.

uvloop's timers live in libuv and ignore an overridden ``time()``, so virtual time
always uses this stdlib-based loop.
"""

from __future__ import annotations

import asyncio
import selectors
from typing import Any

__all__ = ["VirtualTimeLoop"]


class _JumpingSelector(selectors.BaseSelector):
    """Delegates to a real selector, but turns idle waits into clock jumps."""

    def __init__(self, inner: selectors.BaseSelector, loop: VirtualTimeLoop) -> None:
        self._inner = inner
        self._loop = loop

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._inner.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.modify(fileobj, events, data)

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        ready = self._inner.select(0)
        if ready or (timeout is not None and timeout <= 0):
            return ready
        if timeout is None:  # no timer at all: only another thread can wake us
            return self._inner.select(None)
        self._loop.advance(timeout)
        return []

    def close(self) -> None:
        self._inner.close()

    def get_key(self, fileobj: Any) -> selectors.SelectorKey:
        return self._inner.get_key(fileobj)

    def get_map(self) -> Any:
        return self._inner.get_map()


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """A selector event loop on virtual time, starting at 0.0."""

    def __init__(self) -> None:
        self._virtual_now = 0.0
        super().__init__(_JumpingSelector(selectors.DefaultSelector(), self))

    def time(self) -> float:
        """The virtual time, in seconds."""
        return self._virtual_now

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
