"""The requests a layer is waiting on: correlation, deadlines, late replies.

A request is a NEGOTIATION whose ``msg_id`` the reply carries back as ``corr_id``.
Replies are matched here as they arrive, before the layer's inbox, so a layer
blocked in one of its hooks on ``await request(...)`` still gets its answer.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Final

from ._types import RobotId
from .deadlines import Deadlines
from .errors import RequestTimeout
from .message import Message

__all__ = ["PendingRequests"]

_EXPIRED_MEMORY: Final = 1024
"""Timed-out request ids remembered, so that their late replies are dropped."""


class _Waiter:
    __slots__ = ("future", "msg", "peer", "seconds")

    def __init__(
        self, future: asyncio.Future[Message], msg: Message, peer: RobotId | None, seconds: float
    ) -> None:
        self.future = future
        self.msg = msg
        self.peer = peer  # the robot expected to answer an external request; None if internal
        self.seconds = seconds


class PendingRequests:
    """One layer's outstanding requests.

    Args:
        owner: how errors name the layer, e.g. ``"robot 3 Top(L0)"``.
        drop: counts (and logs) a refused reply: ``drop(reason, detail)``.
    """

    __slots__ = ("_deadlines", "_drop", "_expired", "_loop", "_owner", "_waiting")

    def __init__(self, owner: str, drop: Callable[[str, str], None]) -> None:
        self._owner = owner
        self._drop = drop
        self._waiting: dict[int, _Waiter] = {}
        self._expired: dict[int, None] = {}  # insertion-ordered set, oldest evicted first
        self._loop: asyncio.AbstractEventLoop | None = None
        self._deadlines: Deadlines | None = None

    def expect(
        self, msg: Message, peer: RobotId | None, seconds: float, deadline: float
    ) -> asyncio.Future[Message]:
        """Registers ``msg`` (already stamped) as waiting until loop time ``deadline``."""
        deadlines = self._deadlines
        if deadlines is None:
            self._loop = asyncio.get_running_loop()
            deadlines = self._deadlines = Deadlines(self._loop, self._waiting, self._expire)
        future: asyncio.Future[Message] = self._loop.create_future()  # type: ignore[union-attr]
        self._waiting[msg.msg_id] = _Waiter(future, msg, peer, seconds)
        deadlines.add(msg.msg_id, deadline)
        return future

    def forget(self, msg_id: int) -> None:
        """Stops waiting for ``msg_id`` (answered, timed out, cancelled or never sent)."""
        self._waiting.pop(msg_id, None)

    def take(self, reply: Message) -> bool:
        """Hands ``reply`` to the request it answers; True when it was consumed.

        An answer to nobody's request is an ordinary message (False) unless it
        answers a request that timed out, or comes from a robot that was not asked:
        both are dropped and counted (True).
        """
        waiter = self._waiting.get(reply.corr_id)
        if waiter is None:
            if reply.corr_id in self._expired:
                self._drop("late_reply", f"{reply!r} arrived after its request timed out")
                return True
            return False
        if waiter.peer is not None and reply.robot_id != waiter.peer:
            self._drop("reply_from_wrong_robot", f"{reply!r}, expected robot {waiter.peer}")
            return True
        if not waiter.future.done():
            waiter.future.set_result(reply)
        return True

    def _expire(self, msg_id: int) -> None:
        waiter = self._waiting.get(msg_id)
        if waiter is None or waiter.future.done():
            return
        expired = self._expired
        expired[msg_id] = None
        if len(expired) > _EXPIRED_MEMORY:
            del expired[next(iter(expired))]
        msg = waiter.msg
        whom = f"layer {msg.dst_layer}" if waiter.peer is None else f"robot {waiter.peer}"
        waiter.future.set_exception(
            RequestTimeout(
                f"{self._owner}: no reply from {whom} to {type(msg).__name__} "
                f"#{msg.msg_id} within {waiter.seconds:g} s"
            )
        )

    def close(self) -> None:
        """Disarms the deadline timer (the robot stopped)."""
        if self._deadlines is not None:
            self._deadlines.cancel()
