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

Ownership: once sent, a message object belongs to the runtime, which writes its
header. Sending the same object again (or answering a request with the request
object itself) sends a copy, so a message still travelling never changes under it.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, ClassVar, Final

from ._channel import Channel
from ._clock import Clock
from ._counters import LayerCounters
from ._errors import RobotStateError, RuleViolation, UnknownRobotError
from ._layer_requests import Requesting, owned
from ._logs import PrefixLogger
from ._message import Message, MsgType
from ._requests import PendingRequests, ReplyOutcome
from ._types import Level, RobotId

if TYPE_CHECKING:
    from ._robot import Robot

__all__ = ["Layer"]

_NEGOTIATION: Final = MsgType.NEGOTIATION
_NOT_A_REPLY: Final = ReplyOutcome.NOT_A_REPLY
_DELIVERED: Final = ReplyOutcome.DELIVERED


class Layer(Requesting):
    """Base class of every layer. Subclasses override the hooks; see the module docs.

    A layer instance belongs to one robot. The runtime state is set when the robot
    is created, so subclasses may define ``__init__`` without calling ``super()``.
    """

    default_request_timeout: ClassVar[float] = 5.0
    """Simulated seconds a request waits for its reply when no timeout is given."""

    # Timers of wake_after() still to go off; cancelled when the robot stops.
    _wakes: set[asyncio.TimerHandle] | None = None

    # Set by Robot when the stack is connected (thesis ConnectLayers).
    _robot: Robot | None = None
    _level: Level = -1
    _above: Layer | None = None
    _below: Layer | None = None
    _live: bool = False

    # Back-pressure: a layer whose inbox this one filled, and the layer this one
    # is waiting on (to see a cycle of layers waiting on each other).
    _congested: Layer | None = None
    _waiting_on: Layer | None = None

    # -- hooks ---------------------------------------------------------------------

    async def inner_process(self) -> None:
        """The layer's own work: at start and after each batch of delivered messages.

        Return promptly: this layer's messages wait while it runs (replies to its
        own requests and messages passing through it do not).
        """

    async def handle_msg(self, msg: Message) -> None:
        """An external message from the same level of another robot."""

    async def store_intra_msg(self, msg: Message) -> None:
        """An internal ACCEPT or DENY message whose destination is this layer."""

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """The automatic reply to an internal NEGOTIATION (``None``: no reply)."""
        return None

    async def on_restart(self, error: Exception) -> None:
        """Called before the layer runs again after ``error``, under a restart policy.

        Reset here whatever the failure left half done; see :mod:`cas_async._supervision`.
        """

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
        self.robot  # noqa: B018 - raises a clear error when not attached
        return self._log

    @property
    def counters(self) -> LayerCounters:
        """This layer's message counters."""
        self.robot  # noqa: B018 - raises a clear error when not attached
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

    def _stamp(self, robot: Robot, msg: Message, dst: Level) -> None:
        msg.msg_id = next(robot._ids)
        msg.robot_id = robot.robot_id
        msg.src_layer = self._level
        msg.dst_layer = dst
        msg.corr_id = 0

    # -- timers ----------------------------------------------------------------------

    def wake_after(self, seconds: float) -> None:
        """Runs ``inner_process()`` again ``seconds`` simulated seconds from now.

        The event-based way to wait: unlike ``await self.clock.sleep()`` in a hook,
        the layer keeps handling its messages in the meantime. Each call arms one
        wake-up; those still pending when the robot stops are cancelled.
        """
        robot = self._check_live()
        loop = asyncio.get_running_loop()
        wakes = self._wakes
        if wakes is None:
            wakes = self._wakes = set()

        handle: asyncio.TimerHandle | None = None

        def wake() -> None:
            nonlocal handle
            wakes.discard(handle)
            handle = None  # wake and its handle refer to each other: no cycle left to collect
            self._inbox.nudge()

        handle = loop.call_at(robot.clock.loop_deadline(seconds), wake)
        wakes.add(handle)

    def _cancel_wakes(self) -> None:
        for handle in self._wakes or ():
            handle.cancel()
        self._wakes = None

    # -- internal messages -----------------------------------------------------------

    def send_up(self, msg: Message) -> None:
        """Sends an internal message to the layer directly above."""
        robot = self._check_live()
        above = self._above
        if above is None:
            robot._violation("no_layer_above", self, msg)
            return
        msg = owned(msg)
        self._stamp(robot, msg, self._level - 1)
        counters = self._counters
        counters.sent_internal += 1
        by_type = counters.internal_by_type
        by_type[msg.__class__] = by_type.get(msg.__class__, 0) + 1
        if above._inbox.put(msg):
            self._congested = above

    def send_down(self, msg: Message) -> None:
        """Sends an internal message to the layer directly below."""
        robot = self._check_live()
        below = self._below
        if below is None:
            robot._violation("no_layer_below", self, msg)
            return
        msg = owned(msg)
        self._stamp(robot, msg, self._level + 1)
        counters = self._counters
        counters.sent_internal += 1
        by_type = counters.internal_by_type
        by_type[msg.__class__] = by_type.get(msg.__class__, 0) + 1
        if below._inbox.put(msg):
            self._congested = below

    def send_to_layer(self, level: Level, msg: Message) -> None:
        """Sends an internal message to any other layer of this robot.

        A farther layer is reached through every intermediate layer, each of which
        forwards it at once (and counts it) without calling its hooks.
        """
        robot = self._check_live()
        if not self._level_ok(robot, level, msg):
            return
        msg = owned(msg)
        self._stamp(robot, msg, level)
        counters = self._counters
        counters.sent_internal += 1
        by_type = counters.internal_by_type
        by_type[msg.__class__] = by_type.get(msg.__class__, 0) + 1
        self._carry(msg)

    def _level_ok(self, robot: Robot, level: Level, msg: Message) -> bool:
        """Whether ``level`` is another layer of this robot; if not, the drop is counted."""
        if level == self._level:
            robot._violation("to_self", self, msg)
            return False
        if not 0 <= level < len(robot.layers):
            robot._violation("no_such_layer", self, msg)
            return False
        return True

    def _carry(self, msg: Message) -> None:
        """Takes a stamped internal message through the intermediate layers to its own.

        Forwarding happens here, when the message is sent, rather than in each
        intermediate layer's loop: a layer busy in a long hook (a Task layer waiting
        for a motion) must not hold up messages passing between its neighbours.
        """
        dst = msg.dst_layer
        layer = self
        while True:
            layer = layer._below if dst > layer._level else layer._above  # type: ignore[assignment]
            if layer._level == dst:
                break
            layer._counters.forwarded += 1
        if msg.corr_id:
            outcome = layer._requests.take(msg)
            if outcome is not _NOT_A_REPLY:
                if outcome is _DELIVERED:
                    layer._counters.received_internal += 1
                return
        if layer._inbox.put(msg):
            self._congested = layer

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
        # No copy is needed when the message is encoded before send() returns; a
        # robot that passes objects (wire_codec.py) sends a copy of one sent before.
        if robot._passes_objects:
            msg = owned(msg)
        msg.msg_id = next(robot._ids)
        msg.robot_id = robot.robot_id
        msg.src_layer = msg.dst_layer = self._level
        msg.corr_id = 0
        robot._endpoint.send(robot_id, robot._codec.encode(msg))  # type: ignore[union-attr]
        counters = self._counters
        counters.sent_external += 1
        by_type = counters.external_by_type
        by_type[msg.__class__] = by_type.get(msg.__class__, 0) + 1

    def resend(self, robot_id: RobotId, msg: Message) -> None:
        """Sends an external message this layer already sent, again and unchanged.

        It keeps its id, so the other robot handles it at most once: a repetition
        of a message it already has is dropped, and a repeated request it already
        answered is answered again with the same reply. This is how a layer that
        takes answers in ``handle_msg`` (instead of awaiting ``request()``) retries
        over a lossy network, typically from a ``wake_after`` timer.

        Raises:
            RuleViolation: ``msg`` was not sent by this layer as an external message.
            UnknownRobotError: the transport knows no such robot.
        """
        robot = self._check_live()
        if (
            not (msg.msg_id and msg.robot_id == robot.robot_id and msg.src_layer == msg.dst_layer)
            or msg.src_layer != self._level
        ):
            raise RuleViolation(
                f"{self._log.prefix}resend() needs a message this layer sent, got {msg!r}"
            )
        robot._endpoint.send(robot_id, robot._codec.encode(msg))  # type: ignore[union-attr]
        counters = self._counters
        counters.sent_external += 1
        by_type = counters.external_by_type
        by_type[msg.__class__] = by_type.get(msg.__class__, 0) + 1

    def broadcast(self, msg: Message, robots: Iterable[RobotId] | None = None) -> None:
        """Sends one external message to the same level of several robots.

        The message is encoded once. Without ``robots``, it goes to every robot the
        transport knows besides this one.

        Raises:
            UnknownRobotError: after sending to the others, when some robots are unknown.
            ConfigurationError: the robot has no transport.
        """
        robot = self._check_live()
        if robot._passes_objects:
            msg = owned(msg)  # receivers may still hold it
        self._stamp(robot, msg, self._level)
        sent, unknown = robot._broadcast(msg, robots)
        counters = self._counters
        counters.sent_external += sent
        by_type = counters.external_by_type
        by_type[msg.__class__] = by_type.get(msg.__class__, 0) + sent
        if unknown:
            raise UnknownRobotError(f"robot {robot.robot_id}: no address for robots {unknown}")

    def reply(self, request: Message, response: Message) -> None:
        """Answers a request: externally to its robot, or internally to its layer.

        ``response.msg_type`` is kept (ACCEPT by default; set DENY to refuse). The
        request object itself may be sent back as the response.
        """
        robot = self._robot
        if robot is None or not self._live:
            self._check_live()  # raises, naming the reason
        assert robot is not None
        asker, asked_id = request.robot_id, request.msg_id  # before any stamping
        if request.src_layer == request.dst_layer and asker != robot.robot_id:
            response = owned(response)  # a copy if sent before (or the request itself)
            response.msg_id = next(robot._ids)  # stamped inline: the hot path of answers
            response.robot_id = robot.robot_id
            response.src_layer = response.dst_layer = self._level
            response.corr_id = asked_id
            robot._send_reply(asker, asked_id, response)
            counters = self._counters
            counters.sent_external += 1
            by_type = counters.external_by_type
            by_type[response.__class__] = by_type.get(response.__class__, 0) + 1
        else:
            self._reply_internal(robot, request, response)

    def _reply_internal(self, robot: Robot, request: Message, response: Message) -> None:
        asker_level, asked_id = request.src_layer, request.msg_id  # before any stamping
        response = owned(response)
        self._stamp(robot, response, asker_level)
        response.corr_id = asked_id
        counters = self._counters
        counters.sent_internal += 1
        by_type = counters.internal_by_type
        by_type[response.__class__] = by_type.get(response.__class__, 0) + 1
        self._carry(response)

    def silent_for(self, robot_id: RobotId) -> float:
        """Simulated seconds since a message from robot ``robot_id`` was last delivered.

        ``math.inf`` when none ever was. A partner whose silence outlasts what the
        protocol expects (a meeting that should have happened) has gone away.
        """
        robot = self.robot
        heard = robot.last_heard(robot_id)
        return math.inf if heard is None else robot.clock.now() - heard

    # -- delivery from the robot -----------------------------------------------------

    def _accept_external(self, msg: Message) -> bool:
        """Takes an external message from the robot (already checked for level).

        Returns ``False`` when the inbox was full (the drop is counted).
        """
        if msg.corr_id:
            outcome = self._requests.take(msg)
            if outcome is not _NOT_A_REPLY:
                if outcome is _DELIVERED:
                    self._counters.received_external += 1
                return True
        if not self._inbox.offer(msg):
            self.robot._drop(
                "queue_full", f"{type(self).__name__}(L{self._level}) inbox full, {msg!r}"
            )
            return False
        return True
