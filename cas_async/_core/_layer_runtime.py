"""One layer's runtime: its inbox, counters, requests, timers and links, and its loop.

A :class:`~cas_async.Layer` subclass is the user's: hooks, and attributes of its
author's choosing. Everything the runtime needs lives in one :class:`LayerRuntime`
per layer, held by the robot and reached through the layer's one attribute ``_cas``:

* **internal messages** (thesis ``SendUp``/``SendDown``/``ReceiveIntraMsg``):
  stamped, counted and carried through the layers between *when sent*, so a layer
  busy in a long hook never holds up messages passing by;
* **external messages** go out through the robot's :class:`~cas_async._core._outbox.Outbox`;
  those its :class:`~cas_async._core._reception.Reception` accepts arrive in
  :meth:`accept_external`;
* **requests**: a reply is matched to its waiting request as it arrives, before
  the inbox, so a layer blocked on ``await request(...)`` still gets its answer;
  and a layer that overrides ``get_msg_reply`` answers requests *on arrival*,
  even while its task awaits (so two robots asking each other at once are both
  answered);
* **the loop** (thesis Fig. 10): ``inner_process()`` first; then, each time the
  layer wakes: every pending message in one batch (external ones to
  ``handle_msg``, internal ones to ``get_intra_msg_reply`` or
  ``store_intra_msg``), robots that joined or left (``on_robot_joined``,
  ``on_robot_left``), timers that went off (``on_timer``), and ``inner_process()``
  again; until the robot cancels the task;
* **back-pressure** (:mod:`cas_async._core._backpressure`): after a hook that filled another
  layer's inbox, this layer waits until it has drained; **timers** (:mod:`._timers`).
"""

from __future__ import annotations

import asyncio
import math
from collections import deque
from collections.abc import Callable, Hashable, Iterable, Sequence
from typing import Final, TypeVar, final

from .._errors import RequestTimeout, RobotGone, RobotStateError, RuleViolation
from .._types import Level, RobotId
from .._wire._message import Message, MsgType
from ._backpressure import Flow
from ._channel import Channel
from ._counters import LayerCounters, count_sent_internal
from ._hooks import Hooks, Overrides, RobotHandle
from ._logs import DropLog, PrefixLogger
from ._outbox import Outbox, owned
from ._requests import PendingRequests, ReplyOutcome, check_reply
from ._timers import Timers

__all__ = ["LayerRuntime"]

_NEGOTIATION: Final = MsgType.NEGOTIATION
_NOT_A_REPLY: Final = ReplyOutcome.NOT_A_REPLY
_DELIVERED: Final = ReplyOutcome.DELIVERED

R = TypeVar("R", bound=Message)


@final
class LayerRuntime:
    """The runtime state and behaviour of one layer; see the module docs.

    Args:
        layer: the user's layer, whose hooks this runtime calls.
        robot: the robot, as the layer sees it.
        level: the layer's position in the stack (0 = top).
        name: the layer's class name, for logs and errors.
        log: the layer's logger.
        outbox: the robot's outbox (external messages and every message id).
        drops: the robot's count of dropped messages.
        queue_limit: pending messages at which the inbox is full.
        overrides: which optional hooks the layer overrides.
        on_batch: called after each batch when the layer judges termination.
    """

    __slots__ = (
        "above",
        "below",
        "clock",
        "counters",
        "drops",
        "events",
        "failure",
        "flow",
        "inbox",
        "layer",
        "level",
        "live",
        "log",
        "name",
        "on_batch",
        "outbox",
        "overrides",
        "requests",
        "robot",
        "stack",
        "timers",
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
        overrides: Overrides,
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
        self.requests.watch_declined(
            layer.default_request_timeout, self.clock.loop_deadline, log.warning
        )
        self.timers = Timers(self.clock, self.inbox.nudge)
        self.overrides = overrides
        self.on_batch = on_batch
        self.live = False
        self.events: deque[tuple[bool, RobotId]] = deque()  # (joined?, robot) to tell
        self.failure: BaseException | None = None  # raised by a hook outside the task
        self.above: LayerRuntime | None = None
        self.below: LayerRuntime | None = None
        self.stack: Sequence[LayerRuntime] = (self,)
        self.flow = Flow(self.inbox)  # back-pressure: whose inbox it filled, whom it waits on

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
        """The robot stopped: fails the requests still waiting, disarms the timers."""
        self.live = False
        self.requests.close()
        self.timers.close()

    def check_live(self) -> None:
        """Raises ``RobotStateError`` unless the robot runs."""
        if not self.live:
            robot = self.robot
            raise RobotStateError(
                f"{self.name} cannot send: robot {robot.robot_id} is {robot.state}"
            )

    def violation(self, reason: str, msg: Message) -> None:
        """Counts (and logs) a message this layer sent against a rule of the model."""
        self.drops.drop(reason, "%s(L%s) sent %s", self.name, self.level, msg)

    # -- internal messages ---------------------------------------------------------------

    def send_up(self, msg: Message) -> None:
        """Sends an internal message to the layer directly above."""
        level = self.level - 1
        if (self.live and level >= 0) or self.neighbour_ok(level, msg):
            self.send_internal(level, msg if msg.msg_id == 0 else owned(msg))

    def send_down(self, msg: Message) -> None:
        """Sends an internal message to the layer directly below."""
        level = self.level + 1
        if (self.live and level < len(self.stack)) or self.neighbour_ok(level, msg):
            self.send_internal(level, msg if msg.msg_id == 0 else owned(msg))

    def send_to_layer(self, level: Level, msg: Message) -> None:
        """Sends an internal message to any other layer of this robot."""
        if not self.live:
            self.check_live()
        # The common case checked inline (this is the hot path of internal traffic);
        # level_ok() explains and counts the rest.
        if (level != self.level and 0 <= level < len(self.stack)) or self.level_ok(level, msg):
            self.send_internal(level, msg if msg.msg_id == 0 else owned(msg))

    def neighbour_ok(self, level: Level, msg: Message) -> bool:
        """Whether the robot runs and has a layer at ``level``; else counts the drop."""
        if not self.live:
            self.check_live()
        if 0 <= level < len(self.stack):
            return True
        self.violation("no_layer_above" if level < self.level else "no_layer_below", msg)
        return False

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
        count_sent_internal(self.counters, msg.__class__)
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
            self.flow.filled(target.flow)

    def reply_internal(self, request: Message, response: Message) -> None:
        """Answers an internal request: the response goes back to the asking layer."""
        asker, asked_id = request.src_layer, request.msg_id  # before any stamping
        self.send_internal(asker, owned(response), asked_id)

    # -- external messages ---------------------------------------------------------------

    def resend(self, robot_id: RobotId, msg: Message) -> None:
        """Sends an external message this layer already sent, again and unchanged."""
        self.check_live()
        own = msg.msg_id and msg.robot_id == self.outbox.robot_id
        if not (own and msg.src_layer == msg.dst_layer == self.level):
            raise RuleViolation(
                f"{self.log.prefix}resend() needs a message this layer sent, got {msg!r}"
            )
        self.outbox.resend(self.counters, robot_id, msg)

    def broadcast(self, msg: Message, robots: Iterable[RobotId] | None) -> None:
        """Sends one external message to the same level of several robots."""
        self.check_live()
        self.outbox.broadcast(self.counters, self.level, msg, robots)

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

        A reply goes to the request waiting for it; a request is answered at once
        when the layer's ``get_msg_reply`` gives an answer; anything else waits in
        the inbox. Returns ``False`` when the inbox was full (the drop is counted).
        """
        if msg.corr_id:
            outcome = self.requests.take(msg)
            if outcome is not _NOT_A_REPLY:
                if outcome is _DELIVERED:
                    self.counters.received_external += 1
                return True
        elif self.overrides.answers and msg.msg_type == _NEGOTIATION and self.answer(msg):
            return True
        if not self.inbox.offer(msg):
            self.drops.drop("queue_full", "%s(L%s) inbox full, %s", self.name, self.level, msg)
            return False
        return True

    def answer(self, msg: Message) -> bool:
        """Asks ``get_msg_reply`` for the answer to request ``msg``; whether it gave one.

        It runs outside the layer's task (on the message's arrival), so what it
        raises is kept and raised by the task: the layer fails as from any hook.
        """
        if not self.live:
            return False
        try:
            response = self.layer.get_msg_reply(msg)
        except Exception as exc:
            self.failure = exc
            self.inbox.nudge()
            return True  # the request is spent with the layer
        if response is None:
            return False
        self.counters.received_external += 1
        self.outbox.reply(self.counters, self.level, msg.robot_id, msg.msg_id, response)
        return True

    # -- membership ----------------------------------------------------------------------

    def membership_changed(self, robot_id: RobotId, joined: bool) -> None:
        """Robot ``robot_id`` joined (or left): requests waiting on a robot that left fail."""
        if not joined:
            self.requests.fail_peer(
                robot_id, lambda what: RobotGone(f"{self.log.prefix}robot {robot_id} left: {what}")
            )
        if self.live and self.overrides.membership:
            self.events.append((joined, robot_id))
            self.inbox.nudge()

    # -- requests ------------------------------------------------------------------------

    async def request(
        self,
        robot_id: RobotId,
        msg: Message,
        timeout: float | None,
        retries: int,
        reply: type[R] | None,
    ) -> Message:
        """Sends a NEGOTIATION to robot ``robot_id`` and returns its reply (see ``Layer``)."""
        if not self.live:
            self.check_live()
        if robot_id == self.outbox.robot_id:
            self.violation("to_own_robot", msg)
            raise RuleViolation(f"{self.log.prefix}request() to its own robot {robot_id}")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        if msg.msg_id:  # owned(), inline: sent before, so a copy
            msg = owned(msg)
        outbox = self.outbox
        data = outbox.request(self.level, msg)
        msg_id = msg.msg_id
        seconds = self.layer.default_request_timeout if timeout is None else timeout
        requests, deadline = self.requests, self.clock.loop_deadline
        attempt = 0
        while True:
            attempt += 1
            waiting = requests.expect(msg, robot_id, True, seconds, deadline(seconds))
            try:
                if not outbox.transmit(self.counters, robot_id, data, msg.__class__):
                    raise RobotGone(
                        f"{self.log.prefix}robot {robot_id} is not reachable (asked "
                        f"{type(msg).__name__} #{msg_id}, attempt {attempt})"
                    )
                answer = await waiting
                if reply is None or isinstance(answer, reply):  # check_reply's common case
                    return answer
                return check_reply(answer, reply, msg, self.log.prefix)
            except RobotGone as exc:
                exc.peer, exc.attempts = robot_id, attempt
                raise
            except RequestTimeout as exc:
                if attempt > retries:
                    if retries:
                        exc.args = (f"{exc} ({attempt} attempts)",)
                    exc.peer, exc.attempts = robot_id, attempt
                    raise
            finally:
                requests.forget(msg_id)

    async def request_layer(
        self,
        level: Level,
        msg: Message,
        timeout: float | None,
        reply: type[R] | None,
        *,
        neighbour: bool = False,
    ) -> Message:
        """Sends a NEGOTIATION to layer ``level`` of this robot; returns its reply.

        ``neighbour``: asked as the layer above or below (``request_up``/``_down``),
        so a missing one is counted as ``send_up``/``send_down`` count it.
        """
        if not self.live:
            self.check_live()
        if not (self.neighbour_ok(level, msg) if neighbour else self.level_ok(level, msg)):
            where = ("above" if level < self.level else "below") if neighbour else f"{level}"
            raise RuleViolation(f"{self.log.prefix}no layer {where} to ask")
        msg = owned(msg)
        msg.msg_type = _NEGOTIATION
        self.send_internal(level, msg)  # answered once that layer's task has run
        waiting = self.expect(msg, self.outbox.robot_id, False, timeout)
        asked = self.stack[level].flow
        self.flow.asking(asked)  # it handles nothing while it waits
        try:
            answer = await waiting
            if reply is None or isinstance(answer, reply):  # check_reply's common case
                return answer
            return check_reply(answer, reply, msg, self.log.prefix)
        finally:
            self.flow.answered(asked)
            self.requests.forget(msg.msg_id)

    def expect(
        self, msg: Message, peer: RobotId, external: bool, timeout: float | None
    ) -> asyncio.Future[Message]:
        """Registers ``msg`` (stamped) as a request waiting for ``peer``'s answer."""
        seconds = self.layer.default_request_timeout if timeout is None else timeout
        deadline = self.clock.loop_deadline(seconds)
        return self.requests.expect(msg, peer, external, seconds, deadline)

    # -- timers --------------------------------------------------------------------------

    def wake_at(self, at: float, key: Hashable) -> None:
        """Sets timer ``key`` for simulated instant ``at`` (see :mod:`cas_async._core._timers`)."""
        self.check_live()
        self.timers.arm(key, at)

    def wake_after(self, seconds: float, key: Hashable) -> None:
        """Sets timer ``key`` for ``seconds`` simulated seconds from now."""
        self.check_live()
        self.timers.arm(key, self.clock.now() + max(0.0, seconds))

    # -- the loop ------------------------------------------------------------------------

    async def run_loop(self) -> None:
        """Thesis Fig. 10: inner process, then messages in batches, until cancelled."""
        layer = self.layer
        inbox = self.inbox
        pop = inbox.pop
        counters = self.counters
        calls_inner = self.overrides.inner
        on_batch = self.on_batch
        timers = self.timers
        flow = self.flow
        await layer.inner_process()
        if flow.congested is not None:
            await flow.wait_for_room()
        if on_batch is not None:
            on_batch(self)
        while True:
            msg = pop()
            if msg is None:
                await inbox.wait()
                if self.failure is not None:
                    failure, self.failure = self.failure, None
                    raise failure
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
                        else:  # not answered (yet): the asker notes it (the rare path)
                            asked = f"{self.name}(L{self.level})"
                            self.stack[msg.src_layer].requests.declined(msg, asked)
                    else:
                        await layer.store_intra_msg(msg)
                if flow.congested is not None:
                    await flow.wait_for_room()
                msg = pop()
            if self.events:
                await self.tell_events()
            if timers.fired:
                for key in timers.take_fired():
                    await layer.on_timer(key)
                    if flow.congested is not None:
                        await flow.wait_for_room()
            if calls_inner:
                await layer.inner_process()
                if flow.congested is not None:
                    await flow.wait_for_room()
            if on_batch is not None:
                on_batch(self)

    async def tell_events(self) -> None:
        """Tells the layer of the robots that joined or left, in order."""
        events = self.events
        while events:
            joined, robot_id = events.popleft()
            if joined:
                await self.layer.on_robot_joined(robot_id)
            else:
                await self.layer.on_robot_left(robot_id)
