"""A transport for tests that need to be the wire: see and inject what robots receive."""

from __future__ import annotations

from cas_async import MemoryTransport, RobotId, Transport
from cas_async.transport import Codec, DatagramSink, Endpoint, WireCodec


class Tap(Transport):
    """A :class:`MemoryTransport` whose receiving side a test can watch and feed.

    ``received[robot_id]`` keeps every datagram that robot was given (in order),
    ``news[robot_id]`` every ``("joined" | "left", other)`` it was told;
    :meth:`deliver` hands a robot a datagram as if it had come off the wire.
    """

    supports_virtual_time = True

    def __init__(self, inner: Transport | None = None) -> None:
        self.inner = inner if inner is not None else MemoryTransport()
        self.received: dict[RobotId, list[bytes]] = {}
        self.news: dict[RobotId, list[tuple[str, RobotId]]] = {}
        self._sinks: dict[RobotId, DatagramSink] = {}

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        kept = self.received.setdefault(robot_id, [])
        told = self.news.setdefault(robot_id, [])
        self._sinks[robot_id] = sink

        class Recording:
            def datagram_received(self, data: bytes, sender: RobotId | None = None) -> None:
                kept.append(data)
                sink.datagram_received(data, sender)

            def transport_dropped(self, reason: str, detail: str) -> None:
                sink.transport_dropped(reason, detail)

            def robot_joined(self, robot_id: RobotId) -> None:
                told.append(("joined", robot_id))
                sink.robot_joined(robot_id)

            def robot_left(self, robot_id: RobotId) -> None:
                told.append(("left", robot_id))
                sink.robot_left(robot_id)

        return await self.inner.open(robot_id, Recording())

    def wire_codec(self, robot_id: RobotId, codec: Codec) -> WireCodec:
        """The inner transport's: a tap on a transport that passes objects passes objects."""
        return self.inner.wire_codec(robot_id, codec)

    def deliver(self, robot_id: RobotId, data: bytes, sender: RobotId | None = None) -> None:
        """Hands robot ``robot_id`` a datagram from ``sender`` (``None``: a source nobody knows)."""
        self._sinks[robot_id].datagram_received(data, sender)

    def dropped(self, robot_id: RobotId, reason: str, detail: str = "") -> None:
        """Tells robot ``robot_id`` that its transport lost something."""
        self._sinks[robot_id].transport_dropped(reason, detail)
