"""Requests of a layer: ``request()`` to another robot, ``request_layer()`` inside one.

A mixin of :class:`~cas_async._layer.Layer`, kept apart because request and reply
correlation, timeouts, retries and the waiting rules of back-pressure are a
subject of their own. The correlation itself lives in :mod:`cas_async._requests`.
"""

from __future__ import annotations

import asyncio
import copy
from typing import TYPE_CHECKING, ClassVar, Final

from ._errors import RequestTimeout, RuleViolation
from ._message import Message, MsgType
from ._types import Level, RobotId

if TYPE_CHECKING:
    from ._channel import Channel
    from ._counters import LayerCounters
    from ._layer import Layer
    from ._logs import PrefixLogger
    from ._requests import PendingRequests
    from ._robot import Robot

__all__ = ["Requesting"]

_NEGOTIATION: Final = MsgType.NEGOTIATION


def owned(msg: Message) -> Message:
    """The object to stamp and send: ``msg`` the first time, a copy if it was sent before."""
    return msg if msg.msg_id == 0 else copy.copy(msg)


class Requesting:
    """The request methods of :class:`~cas_async._layer.Layer` (see there)."""

    if TYPE_CHECKING:  # what Layer provides
        default_request_timeout: ClassVar[float]
        _robot: Robot | None
        _live: bool
        _level: Level
        _log: PrefixLogger
        _counters: LayerCounters
        _requests: PendingRequests
        _inbox: Channel[Message]
        _waiting_on: Layer | None

        def _check_live(self) -> Robot: ...
        def _level_ok(self, robot: Robot, level: Level, msg: Message) -> bool: ...
        def _stamp(self, robot: Robot, msg: Message, dst: Level) -> None: ...
        def _carry(self, msg: Message) -> None: ...

    async def request(
        self,
        robot_id: RobotId,
        msg: Message,
        *,
        timeout: float | None = None,
        retries: int = 0,
    ) -> Message:
        """Sends a NEGOTIATION to robot ``robot_id`` and returns its reply.

        The other robot answers from ``handle_msg`` with ``self.reply(msg, response)``.
        With ``retries``, a request left unanswered for ``timeout`` is sent again,
        as the same message: the other robot handles it once, and answers a
        repetition with the reply it already sent (which may have been lost).

        Args:
            robot_id: the robot to ask (same level).
            msg: the request; its ``msg_type`` becomes NEGOTIATION.
            timeout: simulated seconds per attempt; ``default_request_timeout``
                when ``None``; ``math.inf`` waits as long as it takes.
            retries: how many times to send it again after a timeout; the whole
                request gives up after ``(retries + 1) * timeout``.

        Raises:
            RequestTimeout: no reply to any attempt (the partner went silent);
                ``attempts`` and ``peer`` say how often and whom it asked.
            RuleViolation: ``robot_id`` is this robot (the drop is counted too).
            RobotStateError: the robot stopped while waiting.
            ValueError: ``retries`` is negative.
        """
        robot = self._robot
        if robot is None or not self._live:
            self._check_live()  # raises, naming the reason
        assert robot is not None
        if robot_id == robot.robot_id:
            robot._violation("to_own_robot", self, msg)  # type: ignore[arg-type]
            raise RuleViolation(f"{self._log.prefix}request() to its own robot {robot_id}")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        msg = owned(msg)
        # Stamped inline, as in send(): the hot path of every round trip.
        msg.msg_type = _NEGOTIATION
        msg.msg_id = msg_id = next(robot._ids)
        msg.robot_id = robot.robot_id
        msg.src_layer = msg.dst_layer = self._level
        msg.corr_id = 0
        data = robot._codec.encode(msg)  # type: ignore[union-attr]
        counters = self._counters
        by_type = counters.external_by_type
        send = robot._endpoint.send
        attempt = 0
        while True:
            reply = self._expect(robot, msg, robot_id, True, timeout)
            try:
                send(robot_id, data)
                counters.sent_external += 1
                by_type[msg.__class__] = by_type.get(msg.__class__, 0) + 1
                return await reply
            except RequestTimeout as exc:
                attempt += 1
                if attempt > retries:
                    if retries:
                        exc.args = (f"{exc} ({attempt} attempts)",)
                    exc.peer, exc.attempts = robot_id, attempt
                    raise
            finally:
                self._requests.forget(msg_id)

    async def request_down(self, msg: Message, *, timeout: float | None = None) -> Message:
        """Sends a NEGOTIATION to the layer below and returns its automatic reply."""
        return await self.request_layer(self._level + 1, msg, timeout=timeout)

    async def request_up(self, msg: Message, *, timeout: float | None = None) -> Message:
        """Sends a NEGOTIATION to the layer above and returns its automatic reply."""
        return await self.request_layer(self._level - 1, msg, timeout=timeout)

    async def request_layer(
        self, level: Level, msg: Message, *, timeout: float | None = None
    ) -> Message:
        """Sends a NEGOTIATION to layer ``level`` of this robot; returns its reply.

        The reply comes from that layer's ``get_intra_msg_reply``.

        Raises:
            RequestTimeout: no reply in time.
            RuleViolation: ``level`` is this layer's or outside the stack (counted too).
            RobotStateError: the robot stopped while waiting.
        """
        robot = self._check_live()
        if not self._level_ok(robot, level, msg):
            raise RuleViolation(f"{self._log.prefix}no layer {level} to ask")
        msg = owned(msg)
        msg.msg_type = _NEGOTIATION
        self._stamp(robot, msg, level)
        reply = self._expect(robot, msg, robot.robot_id, False, timeout)
        counters = self._counters
        counters.sent_internal += 1
        by_type = counters.internal_by_type
        by_type[msg.__class__] = by_type.get(msg.__class__, 0) + 1
        self._carry(msg)
        # While it waits for the answer this layer handles nothing: a layer that waits
        # for room in this layer's inbox must not wait for it (see layer_loop).
        asked = robot.layers[level]
        self._waiting_on = asked
        self._inbox.release_room_waiters()
        try:
            return await reply
        finally:
            self._waiting_on = None
            self._requests.forget(msg.msg_id)

    def _expect(
        self,
        robot: Robot,
        msg: Message,
        peer: RobotId,
        external: bool,
        timeout: float | None,
    ) -> asyncio.Future[Message]:
        seconds = self.default_request_timeout if timeout is None else timeout
        deadline = robot.clock.loop_deadline(seconds)
        return self._requests.expect(msg, peer, external, seconds, deadline)
