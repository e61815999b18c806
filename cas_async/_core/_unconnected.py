"""The endpoint of a robot created without a transport: every use says what is missing."""

from __future__ import annotations

from collections.abc import Iterable
from typing import NoReturn, final

from .._errors import ConfigurationError
from .._types import Address, RobotId
from ._transport_contract import Endpoint

__all__ = ["Unconnected"]


@final
class Unconnected(Endpoint):
    """Stands in for an endpoint, so the send path needs no ``None`` check."""

    max_datagram_size = 64 * 1024

    def __init__(self, robot_id: RobotId) -> None:
        self.robot_id = robot_id

    @property
    def address(self) -> Address:
        """None: nobody can reach this robot."""
        return None

    def _refuse(self) -> NoReturn:
        raise ConfigurationError(
            f"robot {self.robot_id} has no transport: pass transport=... to Robot to "
            "exchange messages with other robots"
        )

    def send(self, robot_id: RobotId, data: bytes) -> None:
        """Raises ``ConfigurationError``."""
        self._refuse()

    def peers(self) -> Iterable[RobotId]:
        """Raises ``ConfigurationError`` (a broadcast would otherwise do nothing silently)."""
        self._refuse()

    def knows(self, robot_id: RobotId) -> bool:
        """False: this robot reaches nobody."""
        return False

    def close(self) -> None:
        """Nothing to close."""
