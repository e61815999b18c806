"""An endpoint that wraps another's: the base of the faulty and authenticated transports.

A wrapping transport opens an inner endpoint per robot and hands the robot its own
endpoint around it. Where the robot is, whom it knows and whether it hears of
robots joining and leaving are the inner endpoint's; closing closes it. A wrapper
changes what it must, and :meth:`~WrappingEndpoint.send` always.
"""

from __future__ import annotations

from collections.abc import Iterable

from .._core._transport_contract import Endpoint
from .._types import Address, RobotId

__all__ = ["WrappingEndpoint"]


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
