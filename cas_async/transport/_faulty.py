"""A transport wrapper that makes the wire between robots lossy, late and unruly.

:class:`FaultyTransport` wraps any :class:`~cas_async._core._transport_contract.Transport`
(memory or UDP) and models a bad network between the robots: each datagram may be
lost, delivered twice, delayed, or held back so that later datagrams overtake it,
as :class:`Faults` says. Robots and layers see an ordinary endpoint; protocols are
tested against the faults they must survive.

Faults apply on the **sending** side only: ``send()`` decides the fate of each
datagram, then hands the surviving copies to the inner endpoint (at once, or from a
loop timer after their delay); receiving is the inner transport's, untouched. A
broadcast is several ``send()`` calls, each decided on its own. ``send()`` keeps the
endpoint contract: an unknown robot or a closed endpoint raises at once, even when
the datagram would have been lost.

Determinism: each sending robot has a random generator of its own, seeded by the
transport's ``seed`` and the robot's id, that draws every decision about its
datagrams: the same sends of a robot get the same faults, whatever the other
robots do and whichever process runs them. With virtual time and the memory
transport the sends themselves are deterministic, hence so is the whole run.

Counts (:attr:`FaultyTransport.stats`, totals over all endpoints):

* ``sent``: datagrams given to ``send()`` (that passed its checks);
* ``lost``: copies that never reached the inner endpoint: lost by chance, or
  found the inner endpoint closed or the peer unknown when their delay ran out;
* ``duplicated``: extra copies made;
* ``reordered``: copies held back;
* ``delayed``: copies given a delay above zero;
* ``lost_at_close``: copies still delayed or held back when their endpoint closed.

Copies handed to the inner endpoint = ``sent + duplicated - lost - lost_at_close``
once every endpoint is closed.
"""

from __future__ import annotations

import asyncio
import math
import random
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, final

from .._core._transport_contract import DatagramSink, Endpoint, Transport
from .._errors import RobotStateError, UnknownRobotError
from .._time._clock import Clock
from .._types import RobotId
from ._wrapping import WrappingEndpoint, WrappingTransport

if TYPE_CHECKING:
    pass

__all__ = ["Faults", "FaultyTransport"]

DEFAULT_HOLD: Final = 0.05
"""Simulated seconds a held-back datagram waits for a later one to overtake it."""

_STATS: Final = ("sent", "lost", "duplicated", "reordered", "delayed", "lost_at_close")


def _probability(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"Faults.{name} must be a number in [0, 1], got {value!r}")
    if not 0.0 <= value <= 1.0:  # also refuses nan
        raise ValueError(f"Faults.{name} must be in [0, 1], got {value!r}")
    return float(value)


@dataclass(frozen=True, slots=True)
class Faults:
    """What the wire does to each datagram; all zero is a perfect wire.

    Attributes:
        loss: probability that a datagram is lost.
        duplicate: probability that a datagram (not lost) is delivered twice; the
            copy gets its own delay and reordering.
        reorder: probability that a copy is held back until the sending endpoint
            sends its next datagram (or ``hold`` simulated seconds pass).
        delay: ``(min, max)`` extra latency of each copy, simulated seconds, drawn
            uniformly; ``(0, 0)`` sends at once.

    Raises:
        ValueError: a probability is not in [0, 1], or ``delay`` is not two finite
            numbers with ``0 <= min <= max``; the message names the field.
    """

    loss: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    delay: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        # Normalised in place (frozen): ints become floats, a [min, max] list a tuple.
        for name in ("loss", "duplicate", "reorder"):
            object.__setattr__(self, name, _probability(name, getattr(self, name)))
        delay = self.delay
        if (
            not isinstance(delay, tuple | list)
            or len(delay) != 2
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in delay)
        ):
            raise ValueError(f"Faults.delay must be (min, max) seconds, got {delay!r}")
        low, high = float(delay[0]), float(delay[1])
        if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
            raise ValueError(
                f"Faults.delay must be finite with 0 <= min <= max, got {tuple(delay)!r}"
            )
        object.__setattr__(self, "delay", (low, high))

    @property
    def any(self) -> bool:
        """Whether anything at all happens to datagrams."""
        return bool(self.loss or self.duplicate or self.reorder or self.delay[1])


@final
class _Pending:
    """A copy waiting on a loop timer: its delay, or its release when held back."""

    __slots__ = ("data", "delay", "handle", "robot_id")

    def __init__(self, robot_id: RobotId, data: bytes, delay: float) -> None:
        self.robot_id = robot_id
        self.data = data
        self.delay = delay  # still to wait once released (held copies only)
        self.handle: asyncio.TimerHandle | None = None


@final
class FaultyEndpoint(WrappingEndpoint):
    """An endpoint of a :class:`FaultyTransport`: faults on send, the rest delegated."""

    __slots__ = ("_closed", "_delayed", "_held", "_loop", "_net", "_rng")

    def __init__(
        self, transport: FaultyTransport, inner: Endpoint, loop: asyncio.AbstractEventLoop
    ) -> None:
        super().__init__(inner)
        self._net = transport
        self._loop = loop
        self._rng = transport.random_for(inner.robot_id)
        self._closed = False
        self._delayed: set[_Pending] = set()
        self._held: list[_Pending] = []  # in the order they were held back

    def send(self, robot_id: RobotId, data: bytes) -> None:
        """Sends ``data`` through the faults (see the module docs).

        Raises:
            UnknownRobotError: the inner endpoint knows no ``robot_id``.
            RobotStateError: this endpoint is closed.
        """
        if self._closed:
            raise RobotStateError(f"robot {self.robot_id}: endpoint is closed")
        if not self._inner.knows(robot_id):
            raise UnknownRobotError(f"robot {self.robot_id}: no address for robot {robot_id}")
        net = self._net
        stats, rng, faults = net._stats, self._rng, net.faults
        stats["sent"] += 1
        # Copies held back before this datagram go out after it: it overtakes them.
        overtaken, self._held = self._held, []
        try:
            if rng.random() < faults.loss:
                stats["lost"] += 1
            else:
                copies = 2 if rng.random() < faults.duplicate else 1
                stats["duplicated"] += copies - 1
                for _ in range(copies):
                    self._dispatch(robot_id, data, faults, rng)
        finally:  # even if the inner endpoint raised: they are out of _held, so go now
            for pending in overtaken:
                assert pending.handle is not None
                pending.handle.cancel()
                self._after(pending.delay, pending.robot_id, pending.data, now=False)

    def _dispatch(self, robot_id: RobotId, data: bytes, faults: Faults, rng: random.Random) -> None:
        """Draws one copy's delay and whether it is held back, and sends or schedules it."""
        stats = self._net._stats
        low, high = faults.delay
        delay = rng.uniform(low, high) if high > 0 else 0.0
        if delay > 0:
            stats["delayed"] += 1
        if rng.random() < faults.reorder:
            stats["reordered"] += 1
            pending = _Pending(robot_id, data, delay)
            pending.handle = self._loop.call_at(
                self._deadline(self._net.hold), self._release, pending
            )
            self._held.append(pending)
        else:
            self._after(delay, robot_id, data, now=True)

    def _after(self, delay: float, robot_id: RobotId, data: bytes, *, now: bool) -> None:
        """Sends after ``delay`` simulated seconds; ``now``: this is the caller's own send."""
        if delay > 0:
            pending = _Pending(robot_id, data, 0.0)
            pending.handle = self._loop.call_at(self._deadline(delay), self._fire, pending)
            self._delayed.add(pending)
        elif now:
            # The caller's datagram, checked above: the inner endpoint's errors are its own.
            self._inner.send(robot_id, data)
        else:
            self._emit(robot_id, data)

    def _deadline(self, seconds: float) -> float:
        clock = self._net.clock
        return clock.loop_deadline(seconds) if clock is not None else self._loop.time() + seconds

    def _release(self, pending: _Pending) -> None:
        """Timer: nothing overtook a held-back copy within ``hold``; it goes on its way."""
        if pending in self._held:
            self._held.remove(pending)
            self._after(pending.delay, pending.robot_id, pending.data, now=False)

    def _fire(self, pending: _Pending) -> None:
        """Timer: a delayed copy's time has come."""
        self._delayed.discard(pending)
        self._emit(pending.robot_id, pending.data)

    def _emit(self, robot_id: RobotId, data: bytes) -> None:
        # Runs from timers and for copies another send released: nobody to raise to,
        # so a peer gone meanwhile is a lost datagram, as on a real wire.
        try:
            self._inner.send(robot_id, data)
        except (UnknownRobotError, RobotStateError):
            self._net._stats["lost"] += 1

    def close(self) -> None:
        """Drops the copies still delayed or held back (``lost_at_close``), closes the inner one."""
        if self._closed:
            return
        self._closed = True
        pending = [*self._delayed, *self._held]
        for copy in pending:
            assert copy.handle is not None
            copy.handle.cancel()
        self._net._stats["lost_at_close"] += len(pending)
        self._delayed.clear()
        self._held.clear()
        super().close()


@final
class FaultyTransport(WrappingTransport):
    """Wraps ``inner`` so that every datagram sent through it meets ``faults``.

    Args:
        inner: the transport that actually carries the datagrams.
        faults: what happens to them; the attribute may be replaced between sends
            to change the conditions during a run.
        seed: seeds the random generator that decides every fault.
        clock: converts delays (simulated seconds) to loop time; without one,
            delays are event-loop seconds.
        hold: simulated seconds a held-back copy waits for a later datagram of its
            endpoint before it goes anyway.

    Raises:
        ValueError: ``hold`` is negative or not finite.
    """

    def __init__(
        self,
        inner: Transport,
        faults: Faults,
        *,
        seed: int = 0,
        clock: Clock | None = None,
        hold: float = DEFAULT_HOLD,
    ) -> None:
        if not (math.isfinite(hold) and hold >= 0):
            raise ValueError(f"hold must be a finite number of seconds >= 0, got {hold!r}")
        super().__init__(inner)
        self.faults = faults
        self.seed = seed
        self.clock = clock
        self.hold = float(hold)
        self._rngs: dict[RobotId, random.Random] = {}
        self._stats = dict.fromkeys(_STATS, 0)

    def random_for(self, robot_id: RobotId) -> random.Random:
        """The generator that decides the faults of ``robot_id``'s datagrams.

        One per robot, kept over its endpoints: a robot that opens again goes on
        where it was.
        """
        rng = self._rngs.get(robot_id)
        if rng is None:
            rng = self._rngs[robot_id] = random.Random(f"{self.seed}/{robot_id}")
        return rng

    @property
    def stats(self) -> dict[str, int]:
        """Counts so far, totals over all endpoints (a copy; see the module docs)."""
        return dict(self._stats)

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        """Opens the inner transport's endpoint for the robot and wraps it.

        Raises:
            ConfigurationError: as the inner transport's ``open``.
        """
        inner = await self.inner.open(robot_id, sink)
        return FaultyEndpoint(self, inner, asyncio.get_running_loop())

    def __repr__(self) -> str:
        return f"FaultyTransport({self.inner!r}, {self.faults!r}, seed={self.seed})"
