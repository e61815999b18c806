"""The transport interface: how a robot's external messages move as bytes.

This is the thesis's Communication/CommInterface pair. A :class:`Transport` is
shared by the robots that can reach each other through it; each robot opens one
:class:`Endpoint` on it. Layers never see either: they send to a robot id, the
robot encodes the message and hands the bytes to its endpoint, and incoming bytes
come back through a :class:`DatagramSink` (the robot's reception). Addresses are opaque, and
nothing assumes that all robots share a process, so a brokered or multi-host
backend fits behind the same interface.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable
from typing import TYPE_CHECKING, Protocol

from .._types import Address, RobotId

if TYPE_CHECKING:
    from .._wire._codec import Codec
    from .._wire._payloads import WireCodec
    from .._wire._presence import PresenceSeal

__all__ = ["DatagramSink", "Endpoint", "LossCounter", "Transport", "drop_socket_error"]


class LossCounter(Protocol):
    """Anything told about datagrams a transport lost or refused."""

    def transport_dropped(self, reason: str, detail: str) -> None:
        """Called when the transport lost or refused something (counted by reason)."""


class DatagramSink(LossCounter, Protocol):
    """What an endpoint delivers to: each robot's reception, given to :meth:`Transport.open`."""

    def datagram_received(self, data: bytes, sender: RobotId | None = None) -> None:
        """Called with each datagram for this robot, in arrival order.

        ``sender`` is the robot the transport knows the datagram came from (its
        source address, or an authenticated id), ``None`` when it knows no robot
        there. A datagram from ``None`` speaks for nobody and is refused undecoded
        (``unknown_source``); one whose header claims another robot than
        ``sender`` is a spoof (``spoofed_sender``).
        """

    def robot_joined(self, robot_id: RobotId) -> None:
        """Robot ``robot_id`` can be reached through the transport from now on.

        Transports that learn of robots coming and going (in-process ones, a
        directory, a discovery service) say so; static ones need not.
        """

    def robot_left(self, robot_id: RobotId) -> None:
        """Robot ``robot_id`` can no longer be reached through the transport."""


def drop_socket_error(sink: LossCounter, exc: Exception) -> None:
    """Counts a datagram lost to a socket error (counted as ``transport.socket_error``).

    A peer the socket cannot reach is a lost datagram, as UDP allows; it must not
    end the layer that sent it.
    """
    sink.transport_dropped("socket_error", f"{type(exc).__name__}: {exc}")


class Endpoint(ABC):
    """One robot's attachment to a transport."""

    robot_id: RobotId
    max_datagram_size: int
    """Largest datagram this endpoint can carry, in bytes."""

    @property
    @abstractmethod
    def address(self) -> Address:
        """Where other robots reach this one (opaque)."""

    @abstractmethod
    def send(self, robot_id: RobotId, data: bytes) -> None:
        """Sends one datagram, without waiting. Delivery is not guaranteed.

        Raises:
            UnknownRobotError: no address is known for ``robot_id``.
            RobotStateError: the endpoint is closed.
        """

    @abstractmethod
    def peers(self) -> Iterable[RobotId]:
        """The other robots this endpoint knows an address for (broadcast targets)."""

    @abstractmethod
    def knows(self, robot_id: RobotId) -> bool:
        """Whether this endpoint can send to ``robot_id`` (see ``Layer.knows``)."""

    @abstractmethod
    def close(self) -> None:
        """Stops sending and receiving; idempotent."""

    def follow_membership(self, follow: bool) -> None:
        """Whether the sink hears of robots joining and leaving (``robot_joined``/``left``).

        Off when opened: a robot turns it on while its layers run, and off when
        they stop, so news that nothing running could use is not sent (a swarm
        of n robots opens and closes in n steps, not n squared). Transports that
        report no membership ignore it.
        """
        return  # default: no membership news to give


class Transport(ABC):
    """Creates endpoints; one instance is shared by the robots it connects."""

    supports_virtual_time: bool = False
    """Whether robots on this transport can run on a virtual clock."""

    authenticated: bool = False
    """Whether an authenticating wrapper signs and checks every datagram of this
    transport (set by the wrapper); a UDP transport binding beyond loopback without
    it warns."""

    def require_proof(self, seal: PresenceSeal) -> None:
        """From now on, robots' presence learnt from the network counts only if ``seal`` proves it.

        Called by an authenticating wrapper (with a swarm key) before robots open. A
        transport that learns where robots live from what others announce (Zenoh's
        liveliness tokens) signs its own robots' announcements with ``seal`` and
        believes only those it verifies; transports whose membership nobody else can
        announce (in one process, or a fixed directory) have nothing to prove.

        Raises:
            ConfigurationError: robots are attached already.
        """
        return  # default: nothing announced, nothing to prove

    @abstractmethod
    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        """Attaches a robot; its incoming datagrams go to ``sink``.

        Raises:
            ConfigurationError: the robot id is already attached, or cannot be bound.
        """

    def wire_codec(self, robot_id: RobotId, codec: Codec) -> WireCodec:
        """What robot ``robot_id`` turns its messages into for this transport, and back.

        ``codec`` (bytes) for a transport that moves bytes, as every transport that
        may leave the process does; an in-process transport that passes message
        objects returns a :class:`~cas_async._wire._payloads.PassThrough`.

        Raises:
            ConfigurationError: the robot cannot use this transport with that codec.
        """
        return codec
