"""A layer's timers: named, at absolute instants, replaced when armed again, never early.

A layer arms a timer with ``wake_at(t, key)`` or ``wake_after(seconds, key)``.
The key names it: arming the same key again moves that timer (it never stacks a
second one), ``cancel_wake(key)`` disarms it, and when it goes off the layer's
``on_timer(key)`` hook is told which one it was (then ``inner_process()`` runs,
as after a batch of messages). The default key is ``None``.

A timer never goes off before its instant, on any clock: the deadline is kept in
simulated time, and a timer that the event loop runs a hair early (clock
rounding) is armed again for what is left, so that ``on_timer`` always finds
``clock.now() >= t``.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Hashable, Iterator
from typing import final

from .._time._clock import Clock

__all__ = ["Timers"]


@final
class Timers:
    """One layer's timers, by key; see the module docs.

    Args:
        clock: the robot's clock (deadlines are simulated instants).
        ring: called when a timer has gone off, to wake the layer's task.
    """

    __slots__ = ("_armed", "_clock", "_ring", "fired")

    def __init__(self, clock: Clock, ring: Callable[[], None]) -> None:
        self._clock = clock
        self._ring = ring
        self._armed: dict[Hashable, tuple[float, asyncio.TimerHandle]] = {}
        self.fired: dict[Hashable, None] = {}
        """Timers gone off and not told yet, in firing order (the layer's loop checks it)."""

    def arm(self, key: Hashable, at: float) -> None:
        """Sets timer ``key`` to go off at simulated instant ``at`` (replacing its earlier one).

        Raises:
            ValueError: ``at`` is NaN.
        """
        if math.isnan(at):
            raise ValueError(f"timer {key!r}: the instant must be a number, got {at!r}")
        self.cancel(key)
        if at == math.inf:
            return  # never: nothing to arm
        loop = asyncio.get_running_loop()
        when = self._clock.loop_deadline_at(at)
        self._armed[key] = (at, loop.call_at(when, self._go_off, key))

    def _go_off(self, key: Hashable) -> None:
        entry = self._armed.get(key)
        if entry is None:
            return
        at, _ = entry
        clock = self._clock
        if clock.now() < at:  # early by a rounding: again, for what is left
            loop = asyncio.get_running_loop()
            when = max(clock.loop_deadline_at(at), math.nextafter(loop.time(), math.inf))
            self._armed[key] = (at, loop.call_at(when, self._go_off, key))
            return
        del self._armed[key]
        self.fired[key] = None
        self._ring()

    def cancel(self, key: Hashable) -> bool:
        """Disarms timer ``key`` (also gone off but not told yet); whether it was set."""
        entry = self._armed.pop(key, None)
        if entry is not None:
            entry[1].cancel()
            return True
        return self.fired.pop(key, 0) is None  # the value of a fired key is None

    def due(self, key: Hashable) -> float | None:
        """The simulated instant timer ``key`` goes off, ``None`` when it is not set."""
        entry = self._armed.get(key)
        if entry is not None:
            return entry[0]
        return self._clock.now() if key in self.fired else None

    def take_fired(self) -> Iterator[Hashable]:
        """The keys of the timers that went off since the last call, in the order they did.

        A key armed again or cancelled while the ones before it are told is skipped.
        """
        fired = self.fired
        while fired:
            key = next(iter(fired))
            del fired[key]
            yield key

    def __len__(self) -> int:
        return len(self._armed) + len(self.fired)

    def close(self) -> None:
        """Disarms every timer (the robot stopped)."""
        for _, handle in self._armed.values():
            handle.cancel()
        self._armed.clear()
        self.fired.clear()
