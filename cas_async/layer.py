"""The ``Layer`` base class: the hooks users write and the messaging the runtime gives.

A layer is one level of a robot's stack (thesis §4.2). Users override the hooks:

* ``inner_process()``: runs when the layer starts and after each batch of
  messages delivered to it;
* ``handle_msg(msg)``: an external message from the same level of another robot;
* ``store_intra_msg(msg)``: an internal ACCEPT/DENY message for this layer;
* ``get_intra_msg_reply(msg)``: an internal NEGOTIATION for this layer; the
  returned message travels back to the sender automatically (``None``: no reply);
* ``termination_condition()``: the robot's ``run()`` returns once it holds for
  every layer.

The runtime owns the loop (one task per layer), forwarding of internal messages
through intermediate layers, the header, and request/reply correlation. Rule
violations are dropped, counted by reason and logged, never delivered.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable
from typing import TYPE_CHECKING, ClassVar, Final

from ._types import Level, RobotId
from .channel import Channel
from .clock import Clock
from .counters import LayerCounters
from .errors import RequestTimeout, RobotStateError, UnknownRobotError
from .logs import PrefixLogger
from .message import Message, MsgType
from .requests import PendingRequests

if TYPE_CHECKING:
    from .robot import Robot

__all__ = ["Layer"]

_NEGOTIATION: Final = MsgType.NEGOTIATION


class Layer:
    """Base class of every layer. Subclasses override the hooks; see the module docs.

    A layer instance belongs to one robot. The runtime state is set when the robot
    is created, so subclasses may define ``__init__`` without calling ``super()``.
    """

    default_request_timeout: ClassVar[float] = 5.0
    """Simulated seconds a request waits for its reply when no timeout is given."""

    # Set by Robot when the stack is connected (thesis ConnectLayers).
    _robot: Robot | None = None
    _level: Level = -1
    _above: Layer | None = None
    _below: Layer | None = None
    _live: bool = False

    # -- hooks ---------------------------------------------------------------------

    async def inner_process(self) -> None:
        """The layer's own work: at start and after each batch of delivered messages."""

    async def handle_msg(self, msg: Message) -> None:
        """An external message from the same level of another robot."""

    async def store_intra_msg(self, msg: Message) -> None:
        """An internal ACCEPT or DENY message whose destination is this layer."""

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """The automatic reply to an internal NEGOTIATION (``None``: no reply)."""
        return None

    def termination_condition(self) -> bool:
        """True when this layer is done; ``run()`` returns once every layer is.

        Layers that do not override it abstain; when no layer of a robot overrides
        it, ``run()`` lasts until ``stop()``.
        """
        return False

    def _has_termination_condition(self) -> bool:
        return type(self).termination_condition is not Layer.termination_condition

    # -- identity --------------------------------------------------------------------

    @property
    def robot(self) -> Robot:
        """The robot this layer belongs to."""
        if self._robot is None:
            raise RobotStateError(f"{type(self).__name__} is not part of a robot yet")
        return self._robot

    @property
    def robot_id(self) -> RobotId:
        """The id of this layer's robot."""
        return self.robot.robot_id

    @property
    def level(self) -> Level:
        """This layer's position in the stack: 0 is the top."""
        self.robot  # noqa: B018 - raises a clear error when not attached
        return self._level

    @property
    def clock(self) -> Clock:
        """The robot's clock (simulated seconds)."""
        return self.robot.clock

    @property
    def log(self) -> PrefixLogger:
        """A logger whose records name the robot and this layer."""
        return self._log

    @property
    def counters(self) -> LayerCounters:
        """This layer's message counters."""
        return self._counters

    def _attach(self, robot: Robot, level: Level, log: PrefixLogger) -> None:
        self._robot = robot
        self._level = level
        self._log = log
        self._counters = LayerCounters()
        self._inbox: Channel[Message] = Channel(robot.queue_limit)
        self._requests = PendingRequests(log.prefix.rstrip(": "), robot._drop)

    def _check_live(self) -> Robot:
        robot = self._robot
        if robot is None or not self._live:
            state = (
                "is not part of a robot"
                if robot is None
                else f"robot {robot.robot_id} is {robot.state}"
            )
            raise RobotStateError(f"{type(self).__name__} cannot send: {state}")
        return robot

    # -- internal messages -----------------------------------------------------------

    def _stamp(self, robot: Robot, msg: Message, dst: Level) -> None:
        msg.msg_id = next(robot._ids)
        msg.robot_id = robot.robot_id
        msg.src_layer = self._level
        msg.dst_layer = dst
        msg.corr_id = 0

    def send_up(self, msg: Message) -> None:
        """Sends an internal message to the layer directly above."""
        robot = self._check_live()
        above = self._above
        if above is None:
            robot._violation("no_layer_above", self, msg)
            return
        self._stamp(robot, msg, self._level - 1)
        self._counters.sent_internal += 1
        above._inbox.put(msg)

    def send_down(self, msg: Message) -> None:
        """Sends an internal message to the layer directly below."""
        robot = self._check_live()
        below = self._below
        if below is None:
            robot._violation("no_layer_below", self, msg)
            return
        self._stamp(robot, msg, self._level + 1)
        self._counters.sent_internal += 1
        below._inbox.put(msg)

    def send_to_layer(self, level: Level, msg: Message) -> None:
        """Sends an internal message to any layer of this robot.

        Farther layers are reached through every intermediate layer, which forwards
        the message without calling its own hooks.
        """
        robot = self._check_live()
        if level == self._level or not 0 <= level < len(robot.layers):
            robot._violation("to_self" if level == self._level else "no_such_layer", self, msg)
            return
        self._stamp(robot, msg, level)
        self._counters.sent_internal += 1
        self._toward(level)._inbox.put(msg)

    def _toward(self, level: Level) -> Layer:
        neighbour = self._below if level > self._level else self._above
        assert neighbour is not None  # level was checked against the stack
        return neighbour

    # -- external messages -----------------------------------------------------------

    def send(self, robot_id: RobotId, msg: Message) -> None:
        """Sends an external message to the same level of robot ``robot_id``.

        Raises:
            UnknownRobotError: the transport knows no such robot.
            EncodeError: the message cannot be encoded.
            ConfigurationError: the robot has no transport.
        """
        robot = self._robot
        if robot is None or not self._live:
            self._check_live()  # raises, naming the reason
        assert robot is not None
        if robot_id == robot.robot_id:
            robot._violation("to_own_robot", self, msg)
            return
        # The header is stamped inline: this is the hot path of external traffic.
        msg.msg_id = next(robot._ids)
        msg.robot_id = robot.robot_id
        msg.src_layer = msg.dst_layer = self._level
        msg.corr_id = 0
        robot._endpoint.send(robot_id, robot._codec.encode(msg))  # type: ignore[union-attr]
        self._counters.sent_external += 1

    def broadcast(self, msg: Message, robots: Iterable[RobotId] | None = None) -> None:
        """Sends one external message to the same level of several robots.

        The message is encoded once. Without ``robots``, it goes to every robot the
        transport knows besides this one.

        Raises:
            UnknownRobotError: after sending to the others, when some robots are unknown.
        """
        robot = self._check_live()
        self._stamp(robot, msg, self._level)
        sent, unknown = robot._broadcast(msg, robots)
        self._counters.sent_external += sent
        if unknown:
            raise UnknownRobotError(f"robot {robot.robot_id}: no address for robots {unknown}")

    def reply(self, request: Message, response: Message) -> None:
        """Answers a request: externally to its robot, or internally to its layer.

        ``response.msg_type`` is kept (ACCEPT by default; set DENY to refuse).
        """
        robot = self._check_live()
        if request.src_layer == request.dst_layer and request.robot_id != robot.robot_id:
            self._stamp(robot, response, self._level)
            response.corr_id = request.msg_id
            robot._send_external(request.robot_id, response)
            self._counters.sent_external += 1
        else:
            self._reply_internal(robot, request, response)

    def _reply_internal(self, robot: Robot, request: Message, response: Message) -> None:
        self._stamp(robot, response, request.src_layer)
        response.corr_id = request.msg_id
        self._counters.sent_internal += 1
        self._toward(request.src_layer)._accept_internal(response)

    # -- requests --------------------------------------------------------------------

    async def request(
        self, robot_id: RobotId, msg: Message, *, timeout: float | None = None
    ) -> Message:
        """Sends a NEGOTIATION to robot ``robot_id`` and returns its reply.

        The other robot answers from ``handle_msg`` with ``self.reply(msg, response)``.

        Args:
            robot_id: the robot to ask (same level).
            msg: the request; its ``msg_type`` becomes NEGOTIATION.
            timeout: simulated seconds; ``default_request_timeout`` when ``None``.

        Raises:
            RequestTimeout: no reply in time.
        """
        robot = self._check_live()
        msg.msg_type = _NEGOTIATION
        if robot_id == robot.robot_id:
            robot._violation("to_own_robot", self, msg)
            raise self._nobody_to_ask(f"robot {robot_id} is this robot")
        self._stamp(robot, msg, self._level)
        reply = self._expect(robot, msg, robot_id, timeout)
        try:
            robot._send_external(robot_id, msg)
            self._counters.sent_external += 1
            return await reply
        finally:
            self._requests.forget(msg.msg_id)

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
            RequestTimeout: no reply in time (also when the request broke a rule).
        """
        robot = self._check_live()
        msg.msg_type = _NEGOTIATION
        if level == self._level or not 0 <= level < len(robot.layers):
            robot._violation("to_self" if level == self._level else "no_such_layer", self, msg)
            raise self._nobody_to_ask(f"no layer {level} to ask")
        self._stamp(robot, msg, level)
        reply = self._expect(robot, msg, None, timeout)
        self._counters.sent_internal += 1
        self._toward(level)._inbox.put(msg)
        try:
            return await reply
        finally:
            self._requests.forget(msg.msg_id)

    def _nobody_to_ask(self, why: str) -> RequestTimeout:
        return RequestTimeout(
            f"robot {self.robot_id} {type(self).__name__}(L{self._level}): {why}; "
            "the request was dropped (see the drop counters)"
        )

    def _expect(
        self, robot: Robot, msg: Message, peer: RobotId | None, timeout: float | None
    ) -> asyncio.Future[Message]:
        seconds = self.default_request_timeout if timeout is None else timeout
        return self._requests.expect(msg, peer, seconds, robot.clock.loop_deadline(seconds))

    # -- delivery (called by neighbours and by the robot) ----------------------------

    def _accept_internal(self, msg: Message) -> None:
        """Takes an internal message; a reply for a waiting request skips the queue."""
        if msg.corr_id and msg.dst_layer == self._level and self._requests.take(msg):
            self._counters.received_internal += 1
            return
        self._inbox.put(msg)

    def _accept_external(self, msg: Message) -> None:
        """Takes an external message from the robot (already checked for level)."""
        if msg.corr_id and self._requests.take(msg):
            self._counters.received_external += 1
            return
        if not self._inbox.offer(msg):
            self.robot._drop(
                "queue_full", f"{type(self).__name__}(L{self._level}) inbox full, {msg!r}"
            )

    # -- the loop --------------------------------------------------------------------

    async def _run(self) -> None:
        """Thesis Fig. 10: inner process, then messages in batches, until stopped."""
        robot = self.robot
        inbox = self._inbox
        level = self._level
        counters = self._counters
        has_inner = type(self).inner_process is not Layer.inner_process
        has_condition = self._has_termination_condition()
        await self.inner_process()
        if has_condition:
            robot._layer_may_be_done(self)
        while True:
            if not inbox:
                await inbox.wait()
            delivered = False
            while inbox:
                msg = inbox.pop()
                dst = msg.dst_layer
                if dst != level:  # passing through on its way to a farther layer
                    counters.forwarded += 1
                    (self._below if dst > level else self._above)._accept_internal(msg)  # type: ignore[union-attr]
                    continue
                delivered = True
                if msg.src_layer == dst:
                    counters.received_external += 1
                    await self.handle_msg(msg)
                    continue
                counters.received_internal += 1
                if msg.msg_type == _NEGOTIATION and not msg.corr_id:
                    response = await self.get_intra_msg_reply(msg)
                    if response is not None:
                        self._reply_internal(robot, msg, response)
                else:
                    await self.store_intra_msg(msg)
            if delivered:
                if has_inner:
                    await self.inner_process()
                if has_condition:
                    robot._layer_may_be_done(self)
