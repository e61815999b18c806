"""What happens to one robot because of another, at a later instant and in a fixed order.

In a simulation with a network latency ``L``, nothing a robot does reaches another
robot at once: a datagram sent at ``t`` is delivered at ``t + L``, an item handed
over at ``t`` arrives at ``t + L``. :class:`Deliveries` holds those effects until
their instant and then runs them in a fixed order: by instant, then by the *key*
each was given (its kind, the sender, the sender's own count...). Two robots that
act at one instant therefore reach a third in the same order however the robots
are spread over processes, which is what makes a run across processes give the
very results of a run in one.

On a :class:`~cas_async._time._virtual_loop.VirtualTimeLoop` the deliveries of an instant
run when the loop reaches it, before the loop's own timers of that instant (the
loop asks :meth:`Deliveries.next_at` before each jump). On any other loop (scaled
real time) they are run by a timer, in the same order; one that comes due too late
(from another process, over a real network) runs as soon as it can, and is
counted (:attr:`Deliveries.late`, :attr:`Deliveries.most_late`): on scaled time,
how far the simulation fell behind the wall clock.
"""

from __future__ import annotations

import asyncio
import heapq
import math
import weakref
from collections.abc import Callable
from typing import Any, Final, Protocol

from ._loop_timers import timer_pad

__all__ = ["DATAGRAM", "ITEM", "MOTION", "RECEIPT", "Deliveries", "DeliveryHost"]

MOTION: Final = 0
"""Kind of a robot's motion becoming visible to others (first within an instant)."""
ITEM: Final = 1
"""Kind of an item arriving in a robot's hands."""
RECEIPT: Final = 2
"""Kind of the answer to a hand-over reaching its giver."""
DATAGRAM: Final = 3
"""Kind of a datagram reaching a robot."""

Key = tuple[Any, ...]
"""What orders the deliveries of one instant: ``(kind, sender, count, ...)``."""

_OF_LOOP: Final[weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, Deliveries]] = (
    weakref.WeakKeyDictionary()
)


class DeliveryHost(Protocol):
    """A loop that runs its deliveries at their instants before its timers."""

    def host(self, deliveries: Deliveries) -> None:
        """Runs ``deliveries``' due actions as its time reaches them."""


class Deliveries:
    """Actions due at loop instants, run in ``(instant, key)`` order (see the module docs).

    One per event loop (:meth:`of`): every transport and Environment of the loop
    shares it, so their deliveries of one instant are ordered together.
    """

    __slots__ = (
        "_count",
        "_heap",
        "_loop",
        "_pad",
        "_virtual",
        "_waker",
        "_waker_at",
        "late",
        "most_late",
    )

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._heap: list[tuple[float, Key, int, Callable[[], None]]] = []
        self._count = 0  # ties of identical keys keep the order they were given in
        self._virtual = hasattr(loop, "host")
        self._pad = 0.0 if self._virtual else timer_pad(loop)  # no action before its instant
        self._waker: asyncio.Handle | None = None
        self._waker_at = math.inf
        self.late = 0
        """Deliveries given after their instant had passed (scaled real time only)."""
        self.most_late = 0.0
        """Loop seconds by which the latest of them came after its instant."""
        if self._virtual:
            loop.host(self)  # type: ignore[attr-defined]

    @classmethod
    def of(cls, loop: asyncio.AbstractEventLoop | None = None) -> Deliveries:
        """The deliveries of ``loop`` (the running one by default), made on first use."""
        loop = asyncio.get_running_loop() if loop is None else loop
        found = _OF_LOOP.get(loop)
        if found is None:
            # The deliveries hold their loop (and their actions, the robots, hold it
            # too), so a weak key alone never lets a loop go: a new loop's first use
            # forgets the loops closed since, or every run would keep its predecessors.
            for closed in [old for old in _OF_LOOP if old.is_closed()]:
                del _OF_LOOP[closed]
            found = _OF_LOOP[loop] = cls(loop)
        return found

    def __len__(self) -> int:
        return len(self._heap)

    def at(self, when: float, key: Key, action: Callable[[], None]) -> None:
        """Runs ``action`` at loop time ``when``, after that instant's deliveries of smaller keys.

        On scaled real time, an action due at or before now runs as soon as it can.

        Raises:
            ValueError: on virtual time, ``when`` is not after the loop's time now
                (an effect takes time, and the loop's time never falls behind).
        """
        now = self._loop.time()
        if not when > now:
            if self._virtual:
                raise ValueError(f"a delivery is due after now ({now}), not at {when}")
            self.late += 1
            self.most_late = max(self.most_late, now - when)
        self._count += 1
        heapq.heappush(self._heap, (when, key, self._count, action))
        if not self._virtual:
            self._wake_at(self._heap[0][0])

    def next_at(self) -> float:
        """The loop time of the earliest delivery due (``inf``: none)."""
        return self._heap[0][0] if self._heap else math.inf

    def run_due(self, now: float) -> int:
        """Runs every delivery due at or before loop time ``now``, in order; how many ran.

        An action that raises is reported to the loop's exception handler, as a
        loop callback's would be (a virtual loop runs this inside its selector, not
        as a callback): the deliveries after it still run.
        """
        heap, ran = self._heap, 0
        pop = heapq.heappop
        while heap and heap[0][0] <= now:
            action = pop(heap)[3]
            ran += 1
            try:
                action()
            except (SystemExit, KeyboardInterrupt):
                raise
            except BaseException as exc:  # a CancelledError too, as asyncio's Handle does
                self._loop.call_exception_handler(
                    {"message": "a delivery failed", "exception": exc}
                )
        return ran

    def _wake_at(self, when: float) -> None:
        if self._waker is not None:
            if self._waker_at <= when:
                return
            self._waker.cancel()
        # (a loop may answer a call_at in the past with a plain Handle, without when())
        self._waker, self._waker_at = self._loop.call_at(when + self._pad, self._woken), when

    def _woken(self) -> None:
        armed, self._waker, self._waker_at = self._waker_at, None, math.inf
        # Armed a pad late, so the instant it was armed for has come (and a hair more).
        self.run_due(max(self._loop.time(), armed))
        if self._heap:
            self._wake_at(self._heap[0][0])
