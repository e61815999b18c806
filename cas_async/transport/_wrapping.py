"""Transports that wrap another: the bases of the faulty, authenticated and ranged ones.

A wrapping transport opens an inner endpoint per robot and hands the robot its own
endpoint around it. Where the robot is, whom it knows and whether it hears of
robots joining and leaving are the inner endpoint's; closing closes it. A wrapper
changes what it must, and :meth:`~WrappingEndpoint.send` always.
"""

from __future__ import annotations

from collections.abc import Iterable

from .._core._transport_contract import Endpoint, Transport
from .._types import Address, RobotId
from .._wire._presence import PresenceSeal

__all__ = ["WrappingEndpoint", "WrappingTransport"]


class WrappingEndpoint(Endpoint):
    """Delegates everything but :meth:`send` to ``inner`` (see the module docs).

    Args:
        inner: the endpoint this one wraps.
        overhead: bytes each datagram gains on its way through (a trailer, say):
            the largest datagram a robot may send is the inner one's less these.
    """

    __slots__ = ("_inner", "max_datagram_size", "robot_id")

    def __init__(self, inner: Endpoint, overhead: int = 0) -> None:
        self._inner = inner
        self.robot_id = inner.robot_id
        self.max_datagram_size = inner.max_datagram_size - overhead

    @property
    def address(self) -> Address:
        return self._inner.address

    def peers(self) -> Iterable[RobotId]:
        return self._inner.peers()

    def knows(self, robot_id: RobotId) -> bool:
        return self._inner.knows(robot_id)

    def follow_membership(self, follow: bool) -> None:
        self._inner.follow_membership(follow)

    def close(self) -> None:
        self._inner.close()


class WrappingTransport(Transport):
    """A transport around ``inner``: membership, virtual time and proofs are the inner one's.

    Subclasses open the inner transport's endpoint in :meth:`open` and wrap it.
    """

    def __init__(self, inner: Transport) -> None:
        self.inner = inner

    @property
    def supports_virtual_time(self) -> bool:  # type: ignore[override] # read-only here
        """As the inner transport."""
        return self.inner.supports_virtual_time

    @property
    def authenticated(self) -> bool:
        """The inner transport's flag: an authenticating wrapper outside sets it there."""
        return self.inner.authenticated

    @authenticated.setter
    def authenticated(self, value: bool) -> None:
        self.inner.authenticated = value

    def require_proof(self, seal: PresenceSeal) -> None:
        """As the inner transport: membership is the inner transport's."""
        self.inner.require_proof(seal)
