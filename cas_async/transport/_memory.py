"""An in-process transport: bytes exactly as over UDP, or, if asked, the message objects.

Every message is encoded by the sender and decoded by the receiver exactly as over
UDP, so behaviour, limits and errors are the same; only the socket is missing.

Delivery is never a re-entrant call into the receiver: what is sent to a robot
waits in that robot's batch, and one ``loop.call_soon`` per batch hands the whole
batch over on the loop's next pass, in send order. That keeps virtual-time runs
deterministic, and costs one scheduled callback per receiver and pass instead of
one per datagram (as a socket read drains what arrived).

With ``pass_objects=True`` the transport carries message objects instead (see
:mod:`cas_async._wire._payloads`): no encoding, no decoding, and none of their checks.
The endpoints below do not look at what they carry.

A datagram in flight when its receiver closes is still handed to the receiver's
sink, which decides what it means: a stopped robot counts it as ``"not_running"``.
Nothing sent is lost without a count.

Membership: when a robot opens its endpoint, every robot already on the
transport is told it joined; when it closes, the others are told it left.

With a ``latency``, a datagram sent at simulated instant ``t`` is delivered at
``t + latency`` instead (a simulation's network model, see
:mod:`cas_async._time._deliveries`): the datagrams of one instant reach a robot ordered by
sender, then by the order each sender sent them, whatever order the robots ran in.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from typing import TYPE_CHECKING, final

from .._core._transport_contract import DatagramSink, Endpoint, Transport
from .._errors import ConfigurationError, RobotStateError, UnknownRobotError
from .._time._clock import Clock
from .._time._deliveries import DATAGRAM, Deliveries
from .._types import Address, RobotId
from .._wire._codec import DEFAULT_MAX_DATAGRAM
from .._wire._payloads import PassThrough

if TYPE_CHECKING:
    from .._wire._codec import Codec
    from .._wire._payloads import WireCodec

__all__ = ["MemoryTransport"]


@final
class MemoryEndpoint(Endpoint):
    """A robot's attachment to a :class:`MemoryTransport`."""

    __slots__ = (
        "_batch",
        "_closed",
        "_delay",
        "_deliveries",
        "_loop",
        "_network",
        "_sent",
        "_sink",
        "max_datagram_size",
        "robot_id",
    )

    def __init__(
        self, network: MemoryTransport, robot_id: RobotId, sink: DatagramSink, delay: float
    ) -> None:
        self._network = network
        self._sink = sink
        self._loop = loop = asyncio.get_running_loop()
        self._closed = False
        self._batch: list[tuple[bytes, RobotId]] | None = None  # sent, not yet delivered
        self._delay = delay  # loop seconds between a send and its delivery (0: next pass)
        self._deliveries = Deliveries.of(loop) if delay > 0 else None
        self._sent = 0  # this robot's datagrams so far: their order within an instant
        self.robot_id = robot_id
        self.max_datagram_size = network.max_datagram_size

    @property
    def address(self) -> Address:
        return ("memory", self.robot_id)

    def send(self, robot_id: RobotId, data: bytes) -> None:
        if self._closed:
            raise RobotStateError(f"robot {self.robot_id}: endpoint is closed")
        target = self._network._endpoints.get(robot_id)
        if target is None:
            raise UnknownRobotError(f"no robot {robot_id} on this MemoryTransport")
        deliveries = self._deliveries
        if deliveries is not None:
            self._sent += 1
            sender = self.robot_id
            deliveries.at(
                self._loop.time() + self._delay,
                (DATAGRAM, sender, self._sent),
                lambda: target.receive(data, sender),
            )
            return
        batch = target._batch
        if batch is None:
            batch = target._batch = []
            self._loop.call_soon(target._deliver)
        batch.append((data, self.robot_id))

    def _deliver(self) -> None:
        # Taken first: what the sink sends while it handles this batch (a reply to
        # this very robot) starts the next batch, delivered on a later pass.
        batch, self._batch = self._batch or (), None
        received = self._sink.datagram_received
        for data, sender in batch:
            # Also after close: the sink (a stopped robot) counts what arrives late.
            try:
                received(data, sender)
            except Exception as exc:  # a broken sink must not lose the rest of the batch
                self._loop.call_exception_handler(
                    {"message": f"robot {self.robot_id}: sink failed", "exception": exc}
                )

    def receive(self, data: bytes, sender: RobotId) -> None:
        """A datagram whose latency is over: to the sink (also after close: it counts it)."""
        try:
            self._sink.datagram_received(data, sender)
        except Exception as exc:  # a broken sink must not stop the other deliveries
            self._loop.call_exception_handler(
                {"message": f"robot {self.robot_id}: sink failed", "exception": exc}
            )

    def peers(self) -> Iterable[RobotId]:
        # By id: a broadcast reaches them in the same order in one process as across
        # several (its datagrams' faults are drawn in that order).
        return sorted(rid for rid in self._network._endpoints if rid != self.robot_id)

    def knows(self, robot_id: RobotId) -> bool:
        return robot_id in self._network._endpoints

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.follow_membership(False)
            network = self._network
            if network._endpoints.get(self.robot_id) is self:
                del network._endpoints[self.robot_id]
                for other in list(network._followers.values()):
                    other.told_left(self.robot_id)

    def follow_membership(self, follow: bool) -> None:
        followers = self._network._followers
        if follow and not self._closed:
            followers[self.robot_id] = self
        elif followers.get(self.robot_id) is self:
            del followers[self.robot_id]

    def told_joined(self, robot_id: RobotId) -> None:
        """Tells this robot that ``robot_id`` is on the transport from now on."""
        self._sink.robot_joined(robot_id)

    def told_left(self, robot_id: RobotId) -> None:
        """Tells this robot that ``robot_id`` left the transport."""
        self._sink.robot_left(robot_id)


@final
class MemoryTransport(Transport):
    """Connects robots of one process through memory (usable with virtual time).

    Args:
        max_datagram_size: largest datagram, as for a real network.
        pass_objects: pass message objects to the receivers instead of encoding them
            (see :mod:`cas_async._wire._payloads`): faster, but without the size limit and
            encodability checks of a network, so a message that would be refused
            over UDP goes through. Robots on it must run identical stacks.
        latency: simulated seconds between a send and its delivery (see the module
            docs); 0 delivers on the loop's next pass.
        clock: the robots' clock, which says how long ``latency`` lasts on the loop
            (needed with a latency).

    Raises:
        ConfigurationError: a negative or non-finite latency, or a latency without
            a clock.
    """

    supports_virtual_time = True

    def __init__(
        self,
        max_datagram_size: int = DEFAULT_MAX_DATAGRAM,
        *,
        pass_objects: bool = False,
        latency: float = 0.0,
        clock: Clock | None = None,
    ) -> None:
        if not (0.0 <= latency < float("inf")):
            raise ConfigurationError(
                f"MemoryTransport latency must be >= 0 simulated seconds, got {latency!r}"
            )
        if latency > 0 and clock is None:
            raise ConfigurationError("a MemoryTransport with a latency needs the robots' clock")
        self.latency = latency
        self._clock = clock
        self.max_datagram_size = max_datagram_size
        self.pass_objects = pass_objects
        self._pass_through: PassThrough | None = None  # made for the first robot, shared
        self._endpoints: dict[RobotId, MemoryEndpoint] = {}
        self._followers: dict[RobotId, MemoryEndpoint] = {}  # told of joins and leaves

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        """Attaches a robot; raises ``ConfigurationError`` when its id is taken."""
        if robot_id in self._endpoints:
            raise ConfigurationError(
                f"robot {robot_id} is already attached to this MemoryTransport"
            )
        for other in list(self._followers.values()):
            other.told_joined(robot_id)
        delay = 0.0 if self._clock is None else self._clock.loop_seconds(self.latency)
        endpoint = self._endpoints[robot_id] = MemoryEndpoint(self, robot_id, sink, delay)
        return endpoint

    def wire_codec(self, robot_id: RobotId, codec: Codec) -> WireCodec:
        """``codec`` (bytes), or with ``pass_objects`` the :class:`PassThrough` of this transport.

        Raises:
            ConfigurationError: with ``pass_objects``, the robot's stack differs from the
                first robot's.
        """
        if not self.pass_objects:
            return codec
        if self._pass_through is None:
            self._pass_through = PassThrough(codec, robot_id)
            return self._pass_through
        return self._pass_through.admit(robot_id, codec)

    def __repr__(self) -> str:
        kind = ", passing objects" if self.pass_objects else ""
        latency = f", latency {self.latency:g} s" if self.latency else ""
        return f"MemoryTransport({len(self._endpoints)} robots{kind}{latency})"
