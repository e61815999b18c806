"""A simulated radio's reach: datagrams to robots beyond the interaction range are lost.

With an interaction range ``R`` (``[network] range``, see
:class:`~cas_async.sim.Environment`), a robot's datagram reaches another robot only
if that robot is within ``R`` of it when it is sent, exactly as a range query would
list it: the sender where it is, the receiver where it is seen (with the latency).
Beyond, it is lost as on a radio, and counted at the sender as
``transport.out_of_range``; a broadcast reaches the robots in range. Nothing is
raised: a request to a robot out of reach times out, as one whose datagram was lost
(the robot may come back within reach).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import final

from .._core._transport_contract import DatagramSink, Endpoint, Transport
from .._time._clock import Clock
from .._types import RobotId
from .._wire._codec import Codec
from .._wire._payloads import WireCodec
from ..transport._wrapping import WrappingEndpoint, WrappingTransport
from ._environment import Environment

__all__ = ["RangedTransport"]


@final
class RangedTransport(WrappingTransport):
    """``inner``, with datagrams beyond ``environment``'s interaction range lost (see above).

    Raises:
        ValueError: the environment has no interaction range.
    """

    def __init__(self, inner: Transport, environment: Environment, clock: Clock) -> None:
        if environment.interaction_range is None:
            raise ValueError("a RangedTransport needs an Environment with an interaction_range")
        super().__init__(inner)
        self.environment = environment
        self.clock = clock

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        """Opens the inner transport's endpoint for the robot and wraps it."""
        return _RangedEndpoint(self, await self.inner.open(robot_id, sink), sink)

    def wire_codec(self, robot_id: RobotId, codec: Codec) -> WireCodec:
        """As the inner transport's (bytes, or objects in one process)."""
        return self.inner.wire_codec(robot_id, codec)

    def __repr__(self) -> str:
        return f"RangedTransport({self.inner!r}, range={self.environment.interaction_range})"


@final
class _RangedEndpoint(WrappingEndpoint):
    __slots__ = ("_clock", "_environment", "_limit", "_sink")

    def __init__(self, transport: RangedTransport, inner: Endpoint, sink: DatagramSink) -> None:
        super().__init__(inner)
        self._environment = transport.environment
        self._clock = transport.clock
        self._limit = transport.environment.interaction_range
        self._sink = sink

    def send(self, robot_id: RobotId, data: bytes) -> None:
        if self._environment.in_range(self.robot_id, robot_id, self._clock.now()):
            self._inner.send(robot_id, data)
        else:
            self._sink.transport_dropped(
                "out_of_range", f"robot {robot_id} is beyond the interaction range {self._limit:g}"
            )

    def peers(self) -> Iterable[RobotId]:
        environment, now, own = self._environment, self._clock.now(), self.robot_id
        return [peer for peer in self._inner.peers() if environment.in_range(own, peer, now)]
