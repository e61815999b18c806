"""One layer's runtime: its inbox, counters, requests, timers and links, and its loop.

A :class:`~cas_async.Layer` subclass is the user's: it holds the hooks and
whatever attributes its author chooses. Everything the runtime needs to run it
lives here, in one :class:`LayerRuntime` per layer, created and held by the
robot; the layer reaches it through a single attribute (``_cas``) and sees only
the messaging API that delegates to it.

What the runtime does for its layer:

* **internal messages** (thesis ``SendUp``/``SendDown``/``ReceiveIntraMsg``):
  stamped, counted and carried through every intermediate layer *when sent*:
  each intermediate layer forwards it (and counts it) without its hooks being
  called, so a layer busy in a long hook never holds up messages passing by;
* **external messages** go out through the robot's
  :class:`~cas_async._outbox.Outbox`; those the robot's
  :class:`~cas_async._reception.Reception` accepts arrive in :meth:`accept_external`;
* **requests**: a reply is matched to its waiting request as it arrives, before
  the inbox, so a layer blocked on ``await request(...)`` still gets its answer;
* **the loop** (thesis Fig. 10): ``inner_process()`` first, then every pending
  message in one batch (external ones to ``handle_msg``, internal ones to
  ``get_intra_msg_reply`` or ``store_intra_msg``), then ``inner_process()``
  again, until the robot cancels the task;
* **back-pressure**: a send that fills another layer's inbox (see
  :mod:`cas_async._channel`) marks this layer congested; after the hook that
  sent it, this layer waits until that inbox has drained to half its limit;
* **timers** set with ``wake_after``, cancelled when the robot stops.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Iterable, Sequence
from typing import Final, final

from ._channel import Channel
from ._counters import LayerCounters
from ._errors import RequestTimeout, RobotStateError, RuleViolation, UnknownRobotError
from ._hooks import Hooks, RobotHandle
from ._logs import DropLog, PrefixLogger
from ._message import Message, MsgType
from ._outbox import Outbox, owned
from ._requests import PendingRequests, ReplyOutcome
from ._types import Level, RobotId

__all__ = ["LayerRuntime"]

_NEGOTIATION: Final = MsgType.NEGOTIATION
_NOT_A_REPLY: Final = ReplyOutcome.NOT_A_REPLY
_DELIVERED: Final = ReplyOutcome.DELIVERED


@final
class LayerRuntime:
    """The runtime state and behaviour of one layer; see the module docs.

    Args:
        layer: the user's layer, whose hooks this runtime calls.
        robot: the robot, as the layer sees it.
        level: the layer's position in the stack (0 = top).
        name: the layer's class name, for logs and errors.
        outbox: the robot's outbox (external messages and every message id).
        drops: the robot's count of dropped messages.
        queue_limit: pending messages at which the inbox is full.
        calls_inner: whether ``inner_process`` is overridden (runs after each batch).
        on_batch: called after each batch when the layer judges termination.
    """

    __slots__ = (
        "above",
        "below",
        "calls_inner",
        "clock",
        "congested",
        "counters",
        "drops",
        "inbox",
        "layer",
        "level",
        "live",
        "log",
        "name",
        "on_batch",
        "outbox",
        "requests",
        "robot",
        "stack",
        "timers",
        "waiting_on",
    )

    def __init__(
        self,
        layer: Hooks,
        robot: RobotHandle,
        level: Level,
        *,
        name: str,
        log: PrefixLogger,
        outbox: Outbox,
        drops: DropLog,
        queue_limit: int,
        calls_inner: bool,
        on_batch: Callable[[LayerRuntime], None] | None,
    ) -> None:
        self.layer = layer
        self.robot = robot
        self.clock = robot.clock
        self.level = level
        self.name = name
        self.log = log
        self.outbox = outbox
        self.drops = drops
        self.counters = LayerCounters()
        self.inbox: Channel[Message] = Channel(queue_limit)
        self.requests = PendingRequests(log.prefix.rstrip(": "), drops.drop)
        self.calls_inner = calls_inner
        self.on_batch = on_batch
        self.live = False
        self.above: LayerRuntime | None = None
        self.below: LayerRuntime | None = None
        self.stack: Sequence[LayerRuntime] = (self,)
        # Back-pressure: the layer whose inbox this one filled, and the layer this
        # one waits on (for room, or for an answer), to see a cycle of waiting layers.
        self.congested: LayerRuntime | None = None
        self.waiting_on: LayerRuntime | None = None
        self.timers: set[asyncio.TimerHandle] = set()  # wake_after() still to go off

    def link(self, stack: Sequence[LayerRuntime]) -> None:
        """Thesis ConnectLayers: this layer's neighbours in ``stack`` (top first)."""
        self.stack = stack
        self.above = stack[self.level - 1] if self.level > 0 else None
        self.below = stack[self.level + 1] if self.level + 1 < len(stack) else None

    # -- lifecycle -----------------------------------------------------------------------

    def start(self) -> None:
        """The robot runs: the layer may send."""
        self.live = True

    def close(self) -> None:
        """The robot stopped: fails the requests still waiting, cancels the timers."""
        self.live = False
        self.requests.close()
        for handle in self.timers:
            handle.cancel()
        self.timers.clear()

    def check_live(self) -> None:
        """Raises ``RobotStateError`` unless the robot runs."""
        if not self.live:
            robot = self.robot
            raise RobotStateError(
                f"{self.name} cannot send: robot {robot.robot_id} is {robot.state}"
            )

    def violation(self, reason: str, msg: Message) -> None:
        """Counts (and logs) a message this layer sent against a rule of the model."""
        self.drops.drop(reason, f"{self.name}(L{self.level}) sent {msg!r}")

    # -- internal messages ---------------------------------------------------------------

    def send_up(self, msg: Message) -> None:
        """Sends an internal message to the layer directly above."""
        if not self.live:
            self.check_live()
        if self.above is None:
            self.violation("no_layer_above", msg)
            return
        self.send_internal(self.level - 1, owned(msg))

    def send_down(self, msg: Message) -> None:
        """Sends an internal message to the layer directly below."""
        if not self.live:
            self.check_live()
        if self.below is None:
            self.violation("no_layer_below", msg)
            return
        self.send_internal(self.level + 1, owned(msg))

    def send_to_layer(self, level: Level, msg: Message) -> None:
        """Sends an internal message to any other layer of this robot."""
        if not self.live:
            self.check_live()
        # The common case checked inline (this is the hot path of internal traffic);
        # level_ok() explains and counts the rest.
        if (level != self.level and 0 <= level < len(self.stack)) or self.level_ok(level, msg):
            self.send_internal(level, msg if msg.msg_id == 0 else owned(msg))

    def level_ok(self, level: Level, msg: Message) -> bool:
        """Whether ``level`` is another layer of this robot; if not, the drop is counted."""
        if level == self.level:
            self.violation("to_self", msg)
            return False
        if not 0 <= level < len(self.stack):
            self.violation("no_such_layer", msg)
            return False
        return True

    def send_internal(self, dst: Level, msg: Message, corr_id: int = 0) -> None:
        """Stamps, counts and carries an owned internal message to layer ``dst``."""
        self.outbox.stamp(msg, self.level, dst, corr_id)
        counters = self.counters
        counters.sent_internal += 1
        by_type = counters.internal_by_type
        by_type[msg.__class__] = by_type.get(msg.__class__, 0) + 1
        self.carry(msg)

    def carry(self, msg: Message) -> None:
        """Takes a stamped internal message through the intermediate layers to its own.

        Forwarding happens here, when the message is sent, rather than in each
        intermediate layer's loop: a layer busy in a long hook (a Task layer waiting
        for a motion) must not hold up messages passing between its neighbours.
        """
        dst = msg.dst_layer
        stack = self.stack
        step = 1 if dst > self.level else -1
        for passing in range(self.level + step, dst, step):
            stack[passing].counters.forwarded += 1
        target = stack[dst]
        if msg.corr_id:
            outcome = target.requests.take(msg)
            if outcome is not _NOT_A_REPLY:
                if outcome is _DELIVERED:
                    target.counters.received_internal += 1
                return
        if target.inbox.put(msg):
            self.congested = target

    def reply_internal(self, request: Message, response: Message) -> None:
        """Answers an internal request: the response goes back to the asking layer."""
        asker, asked_id = request.src_layer, request.msg_id  # before any stamping
        self.send_internal(asker, owned(response), asked_id)

    # -- external messages ---------------------------------------------------------------

    def resend(self, robot_id: RobotId, msg: Message) -> None:
        """Sends an external message this layer already sent, again and unchanged."""
        self.check_live()
        if (
            not (
                msg.msg_id
                and msg.robot_id == self.outbox.robot_id
                and msg.src_layer == msg.dst_layer
            )
            or msg.src_layer != self.level
        ):
            raise RuleViolation(
                f"{self.log.prefix}resend() needs a message this layer sent, got {msg!r}"
            )
        self.outbox.resend(self.counters, robot_id, msg)

    def broadcast(self, msg: Message, robots: Iterable[RobotId] | None) -> None:
        """Sends one external message to the same level of several robots."""
        self.check_live()
        unknown = self.outbox.broadcast(self.counters, self.level, msg, robots)
        if unknown:
            raise UnknownRobotError(
                f"robot {self.outbox.robot_id}: no address for robots {unknown}"
            )

    def reply(self, request: Message, response: Message) -> None:
        """Answers a request: externally to its robot, or internally to its layer."""
        if not self.live:
            self.check_live()
        asker = request.robot_id
        if request.src_layer == request.dst_layer and asker != self.outbox.robot_id:
            self.outbox.reply(self.counters, self.level, asker, request.msg_id, response)
        else:
            self.reply_internal(request, response)

    def silent_for(self, robot_id: RobotId) -> float:
        """Simulated seconds since a message from robot ``robot_id`` was last delivered."""
        heard = self.robot.last_heard(robot_id)
        return math.inf if heard is None else self.clock.now() - heard

    def accept_external(self, msg: Message) -> bool:
        """Takes an external message from the robot (already checked for level).

        Returns ``False`` when the inbox was full (the drop is counted).
        """
        if msg.corr_id:
            outcome = self.requests.take(msg)
            if outcome is not _NOT_A_REPLY:
                if outcome is _DELIVERED:
                    self.counters.received_external += 1
                return True
        if not self.inbox.offer(msg):
            self.drops.drop("queue_full", f"{self.name}(L{self.level}) inbox full, {msg!r}")
            return False
        return True

    # -- requests ------------------------------------------------------------------------

    async def request(
        self, robot_id: RobotId, msg: Message, timeout: float | None, retries: int
    ) -> Message:
        """Sends a NEGOTIATION to robot ``robot_id`` and returns its reply (see ``Layer``)."""
        if not self.live:
            self.check_live()
        if robot_id == self.outbox.robot_id:
            self.violation("to_own_robot", msg)
            raise RuleViolation(f"{self.log.prefix}request() to its own robot {robot_id}")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        msg = owned(msg)
        data = self.outbox.request(self.level, msg)
        msg_id = msg.msg_id
        attempt = 0
        while True:
            reply = self.expect(msg, robot_id, True, timeout)
            try:
                self.outbox.transmit(self.counters, robot_id, data, msg.__class__)
                return await reply
            except RequestTimeout as exc:
                attempt += 1
                if attempt > retries:
                    if retries:
                        exc.args = (f"{exc} ({attempt} attempts)",)
                    exc.peer, exc.attempts = robot_id, attempt
                    raise
            finally:
                self.requests.forget(msg_id)

    async def request_layer(self, level: Level, msg: Message, timeout: float | None) -> Message:
        """Sends a NEGOTIATION to layer ``level`` of this robot; returns its reply."""
        self.check_live()
        if not self.level_ok(level, msg):
            raise RuleViolation(f"{self.log.prefix}no layer {level} to ask")
        msg = owned(msg)
        msg.msg_type = _NEGOTIATION
        self.outbox.stamp(msg, self.level, level)
        reply = self.expect(msg, self.outbox.robot_id, False, timeout)
        counters = self.counters
        counters.sent_internal += 1
        by_type = counters.internal_by_type
        by_type[msg.__class__] = by_type.get(msg.__class__, 0) + 1
        self.carry(msg)
        # While it waits for the answer this layer handles nothing: a layer that waits
        # for room in this layer's inbox must not wait for it (see wait_for_room).
        self.waiting_on = self.stack[level]
        self.inbox.release_room_waiters()
        try:
            return await reply
        finally:
            self.waiting_on = None
            self.requests.forget(msg.msg_id)

    def expect(
        self, msg: Message, peer: RobotId, external: bool, timeout: float | None
    ) -> asyncio.Future[Message]:
        """Registers ``msg`` (stamped) as a request waiting for ``peer``'s answer."""
        seconds = self.layer.default_request_timeout if timeout is None else timeout
        deadline = self.clock.loop_deadline(seconds)
        return self.requests.expect(msg, peer, external, seconds, deadline)

    # -- timers --------------------------------------------------------------------------

    def wake_after(self, seconds: float) -> None:
        """Runs ``inner_process()`` again ``seconds`` simulated seconds from now."""
        self.check_live()
        loop = asyncio.get_running_loop()
        timers = self.timers
        handle: asyncio.TimerHandle | None = None

        def wake() -> None:
            nonlocal handle
            timers.discard(handle)
            handle = None  # wake and its handle refer to each other: no cycle left to collect
            self.inbox.nudge()

        handle = loop.call_at(self.clock.loop_deadline(seconds), wake)
        timers.add(handle)

    # -- the loop ------------------------------------------------------------------------

    async def run_loop(self) -> None:
        """Thesis Fig. 10: inner process, then messages in batches, until cancelled."""
        layer = self.layer
        inbox = self.inbox
        pop = inbox.pop
        counters = self.counters
        calls_inner = self.calls_inner
        on_batch = self.on_batch
        await layer.inner_process()
        if self.congested is not None:
            await self.wait_for_room()
        if on_batch is not None:
            on_batch(self)
        while True:
            msg = pop()
            if msg is None:
                await inbox.wait()
                msg = pop()
            while msg is not None:  # every message here is for this layer: forwarding is done
                if msg.src_layer == msg.dst_layer:
                    counters.received_external += 1
                    await layer.handle_msg(msg)
                else:
                    counters.received_internal += 1
                    if msg.msg_type == _NEGOTIATION and not msg.corr_id:
                        response = await layer.get_intra_msg_reply(msg)
                        if response is not None:
                            self.reply_internal(msg, response)
                    else:
                        await layer.store_intra_msg(msg)
                if self.congested is not None:
                    await self.wait_for_room()
                msg = pop()
            if calls_inner:
                await layer.inner_process()
                if self.congested is not None:
                    await self.wait_for_room()
            if on_batch is not None:
                on_batch(self)

    async def wait_for_room(self) -> None:
        """Waits while a layer that this one filled drains to half its limit.

        A layer never waits on one that waits, along a chain, on it: two layers
        flooding each other, or a consumer asking its producer, would wait forever.
        One of them goes on instead, which drains the other's sender. A layer that
        starts waiting on one held back by it releases it (``release_room_waiters``),
        so the check is made again.
        """
        target = self.congested
        self.congested = None
        assert target is not None
        while target.inbox.crowded and not target.waits_on(self):
            self.waiting_on = target
            try:
                await target.inbox.room()
            finally:
                self.waiting_on = None

    def waits_on(self, other: LayerRuntime) -> bool:
        """Whether this layer waits, directly or along a chain, on ``other``.

        A layer waits on another while it waits for room in its inbox, or for its
        answer to a request (then it handles nothing either).
        """
        along: LayerRuntime | None = self
        while along is not None:
            if along is other:
                return True
            along = along.waiting_on
        return False
