"""A robot's attachment to a Zenoh transport, and what it needs of the transport."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Protocol, final

from ..._core._transport_contract import DatagramSink, Endpoint
from ..._errors import RobotStateError
from ..._types import Address, RobotId

__all__ = ["ZenohEndpoint", "ZenohNetwork"]


class ZenohNetwork(Protocol):
    """What an endpoint asks of its transport (:class:`~cas_async.ZenohTransport`)."""

    max_datagram_size: int

    @property
    def zid(self) -> str:
        """The Zenoh id of the transport's session."""

    def zid_of(self, robot_id: RobotId) -> str | None:
        """The session robot ``robot_id`` lives in, while its token is alive."""

    def members(self) -> list[RobotId]:
        """Every robot with a live token."""

    def send_from(self, sender: RobotId, receiver: RobotId, data: bytes) -> None:
        """Sends a datagram to ``receiver``, wherever it lives."""

    def follow(self, endpoint: ZenohEndpoint, follow: bool) -> None:
        """Whether ``endpoint``'s robot hears of robots joining and leaving."""

    def detach(self, endpoint: ZenohEndpoint, token: Any) -> None:
        """Called by a closing endpoint."""


@final
class ZenohEndpoint(Endpoint):
    """A robot's attachment to a :class:`~cas_async.ZenohTransport`."""

    __slots__ = ("_closed", "_network", "_token", "max_datagram_size", "robot_id", "sink")

    def __init__(
        self, network: ZenohNetwork, robot_id: RobotId, sink: DatagramSink, token: Any
    ) -> None:
        self._network = network
        self.sink = sink
        """Where this robot's datagrams go."""
        self._token = token
        self._closed = False
        self.robot_id = robot_id
        self.max_datagram_size = network.max_datagram_size

    @property
    def address(self) -> Address:
        return ("zenoh", self._network.zid, self.robot_id)

    def send(self, robot_id: RobotId, data: bytes) -> None:
        if self._closed:
            raise RobotStateError(f"robot {self.robot_id}: Zenoh endpoint is closed")
        self._network.send_from(self.robot_id, robot_id, data)

    def peers(self) -> Iterable[RobotId]:
        return [rid for rid in self._network.members() if rid != self.robot_id]

    def knows(self, robot_id: RobotId) -> bool:
        return self._network.zid_of(robot_id) is not None

    def follow_membership(self, follow: bool) -> None:
        self._network.follow(self, follow and not self._closed)

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._network.detach(self, self._token)
