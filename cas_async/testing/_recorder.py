"""A layer for tests that records what reaches it and answers requests by a function."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from .. import Layer, Message

__all__ = ["Recorder"]

M = TypeVar("M", bound=Message)


class Recorder(Layer):
    """A layer that records what reaches it, and answers requests with ``answer(msg)``.

    ``arrived`` keeps every message that reached the layer, in the order the layer
    took them (a request answered with ``answer`` the moment it arrives, the others
    when the layer's task gets to them); ``external``
    and ``internal`` those that reached ``handle_msg`` and ``store_intra_msg``;
    ``requests`` the NEGOTIATIONs it was asked (by another robot or a neighbour).
    ``answer`` (default: none) returns the reply to a request, or ``None`` to leave
    it unanswered (an external one then reaches ``handle_msg``).

    Args:
        answer: the reply to a request.
    """

    def __init__(self, answer: Callable[[Message], Message | None] | None = None) -> None:
        self.arrived: list[Message] = []
        self.external: list[Message] = []
        self.internal: list[Message] = []
        self.requests: list[Message] = []
        self._answer = answer

    def of_type(self, cls: type[M]) -> list[M]:
        """The messages of class ``cls`` that reached the layer, in order."""
        return [m for m in self.arrived if isinstance(m, cls)]

    def get_msg_reply(self, msg: Message) -> Message | None:
        """An external request: recorded, and answered with ``answer`` at once."""
        self.requests.append(msg)
        reply = self._answer(msg) if self._answer is not None else None
        if reply is not None:  # else it reaches handle_msg, which records it
            self.arrived.append(msg)
        return reply

    async def handle_msg(self, msg: Message) -> None:
        """Recorded."""
        self.arrived.append(msg)
        self.external.append(msg)

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """An internal request: recorded, and answered with ``answer``."""
        self.arrived.append(msg)
        self.requests.append(msg)
        return self._answer(msg) if self._answer is not None else None

    async def store_intra_msg(self, msg: Message) -> None:
        """Recorded."""
        self.arrived.append(msg)
        self.internal.append(msg)
