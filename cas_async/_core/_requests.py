"""The requests a layer is waiting on: correlation, deadlines, late and stray replies.

A request is a NEGOTIATION whose ``msg_id`` the reply carries back as ``corr_id``.
Replies are matched here as they arrive, before the layer's inbox, so a layer
blocked in one of its hooks on ``await request(...)`` still gets its answer. A
reply must come from where the request went: the asked robot for an external
request (same level), this robot's own layers for an internal one. Anything else
that claims to answer a request (a stray, late or repeated reply) is dropped and
counted; it never reaches a hook or a waiting caller.

An internal request that its layer does not answer (``get_intra_msg_reply``
returned ``None``) may be answered later with ``reply()``, or never: the asker
then waits until its timeout, forever with ``math.inf``. Such a request is noted
(:meth:`PendingRequests.declined`, off the hot path: only when no answer came),
logged once if it still waits :data:`OVERDUE` times the asker's default timeout
later, and listed by :meth:`PendingRequests.unanswered` (a run reports them when
it ends).
"""

from __future__ import annotations

import asyncio
import enum
import math
from collections.abc import Callable
from typing import Final

from .._errors import RequestTimeout, RobotStateError, UnexpectedReply
from .._types import RobotId
from .._wire._message import Message
from ._deadlines import Deadlines

__all__ = ["OVERDUE", "PendingRequests", "ReplyOutcome", "check_reply"]

_MEMORY: Final = 256
"""Timed-out and answered request ids remembered per layer, to drop late or repeated replies.

Repeated external replies are already refused by the robot's duplicate check (by
message id), so these only name what reaches a layer anyway; a small memory
keeps a busy layer's footprint flat."""


OVERDUE: Final = 10.0
"""A declined internal request is logged once it has waited this many default timeouts."""
_DECLINED_SLACK: Final = 64
"""Notes of declined requests kept before those no longer waiting are swept out."""


class ReplyOutcome(enum.Enum):
    """What :meth:`PendingRequests.take` did with a message carrying a ``corr_id``."""

    NOT_A_REPLY = 0
    """No request of this layer waits for it: an ordinary message for the hooks."""
    DELIVERED = 1
    """It answered a waiting request."""
    DROPPED = 2
    """It claimed to answer a request but was late, repeated or from the wrong place."""


class _Waiter:
    __slots__ = ("external", "future", "peer", "request", "seconds")

    def __init__(
        self,
        future: asyncio.Future[Message],
        request: Message,
        peer: RobotId,
        external: bool,
        seconds: float,
    ) -> None:
        self.future = future
        self.request = request
        self.peer = peer  # the robot that must answer (this robot, for internal ones)
        self.external = external
        self.seconds = seconds

    @property
    def what(self) -> str:
        """``robot 3 to Query #12``, for errors and drops: formatted only for those."""
        request = self.request
        whom = f"robot {self.peer}" if self.external else f"layer {request.dst_layer}"
        return f"{whom} to {type(request).__name__} #{request.msg_id}"


def _remember(ids: dict[int, None], msg_id: int) -> None:
    ids[msg_id] = None
    if len(ids) > _MEMORY:
        del ids[next(iter(ids))]  # insertion order: the oldest goes first


class PendingRequests:
    """One layer's outstanding requests.

    Args:
        owner: how errors name the layer, e.g. ``"robot 3 Top(L0)"``.
        drop: counts (and logs) a refused reply: ``drop(reason, template, *args)``.
    """

    __slots__ = (
        "_answered",
        "_deadlines",
        "_declined",
        "_drop",
        "_expired",
        "_loop_deadline",
        "_owner",
        "_patience",
        "_waiting",
        "_warn",
    )

    def __init__(self, owner: str, drop: Callable[..., None]) -> None:
        self._owner = owner
        self._drop = drop
        self._patience = math.inf
        self._loop_deadline: Callable[[float], float] | None = None
        self._warn: Callable[..., None] | None = None
        self._waiting: dict[int, _Waiter] = {}
        self._expired: dict[int, None] = {}  # insertion-ordered sets of recent ids
        self._answered: dict[int, None] = {}
        self._deadlines: Deadlines | None = None
        # Internal requests their layer did not answer at once: msg_id -> (the asked
        # layer, the warning's timer). Only get_intra_msg_reply returning None adds.
        self._declined: dict[int, tuple[str, asyncio.TimerHandle | None]] | None = None

    def expect(
        self,
        msg: Message,
        peer: RobotId,
        external: bool,
        seconds: float,
        deadline: float,
    ) -> asyncio.Future[Message]:
        """Registers ``msg`` (already stamped) as waiting until loop time ``deadline``.

        Args:
            msg: the request.
            peer: the robot whose answer is expected (this robot for internal ones).
            external: whether the answer must come from another robot's same level.
            seconds: the timeout, for the error message.
            deadline: when it expires, in event-loop time (``inf``: never).
        """
        deadlines = self._deadlines
        if deadlines is None:
            loop = asyncio.get_running_loop()
            deadlines = self._deadlines = Deadlines(loop, self._waiting, self._expire)
        future: asyncio.Future[Message] = deadlines.loop.create_future()
        self._waiting[msg.msg_id] = _Waiter(future, msg, peer, external, seconds)
        if deadline != math.inf:  # an infinite timeout arms no timer
            deadlines.add(msg.msg_id, deadline)
        return future

    def forget(self, msg_id: int) -> None:
        """Stops waiting for ``msg_id`` (answered, timed out, cancelled or never sent)."""
        self._waiting.pop(msg_id, None)

    def take(self, reply: Message) -> ReplyOutcome:
        """Hands ``reply`` to the request it answers, if any; see :class:`ReplyOutcome`."""
        corr_id = reply.corr_id
        waiter = self._waiting.get(corr_id)
        if waiter is None:
            if corr_id in self._expired:
                self._drop("late_reply", "%s arrived after its request timed out", reply)
            elif corr_id in self._answered:
                self._drop("duplicate_reply", "%s answers a request already answered", reply)
            else:
                return ReplyOutcome.NOT_A_REPLY
            return ReplyOutcome.DROPPED
        external = reply.src_layer == reply.dst_layer
        if reply.robot_id != waiter.peer or external != waiter.external:
            self._drop(
                "reply_from_wrong_place", "%s claims to be the reply from %s", reply, waiter.what
            )
            return ReplyOutcome.DROPPED
        if waiter.future.cancelled():  # the asker stopped waiting (the robot is stopping)
            self._drop("late_reply", "%s arrived after its request was cancelled", reply)
            return ReplyOutcome.DROPPED
        if waiter.future.done():
            self._drop("duplicate_reply", "%s answers a request already answered", reply)
            return ReplyOutcome.DROPPED
        waiter.future.set_result(reply)
        answered = self._answered  # _remember(), inline: every reply comes here
        answered[corr_id] = None
        if len(answered) > _MEMORY:
            del answered[next(iter(answered))]
        return ReplyOutcome.DELIVERED

    def _expire(self, msg_id: int) -> None:
        waiter = self._waiting.get(msg_id)
        if waiter is None or waiter.future.done():
            return
        _remember(self._expired, msg_id)
        waiter.future.set_exception(
            RequestTimeout(
                f"{self._owner}: no reply from {waiter.what} within {waiter.seconds:g} s"
            )
        )

    def watch_declined(
        self,
        patience: float,
        loop_deadline: Callable[[float], float],
        warn: Callable[..., None],
    ) -> None:
        """Logs a declined request (see :meth:`declined`) that waits too long.

        Args:
            patience: the layer's default request timeout, simulated seconds: a
                declined request is logged once it has waited :data:`OVERDUE`
                times that (never, when it is ``inf``).
            loop_deadline: the loop time a timer in some simulated seconds is armed
                for (the clock's ``loop_deadline``).
            warn: logs the warning (a logger's ``warning``).
        """
        self._patience = patience
        self._loop_deadline = loop_deadline
        self._warn = warn

    def declined(self, request: Message, asked: str) -> None:
        """The asked layer gave no answer to ``request`` (``get_intra_msg_reply`` returned None).

        If this layer still waits for it, the request is noted: :meth:`unanswered`
        lists it while it waits, and it is logged once if it still waits
        ``OVERDUE * patience`` simulated seconds from now.

        Args:
            request: the internal request, as it reached the asked layer.
            asked: how to name the asked layer (``"Drive(L1)"``).
        """
        msg_id = request.msg_id
        waiter = self._waiting.get(msg_id)
        if waiter is None or waiter.future.done():
            return  # answered meanwhile, or asked without waiting (a NEGOTIATION sent)
        declined = self._declined
        if declined is None:
            declined = self._declined = {}
        elif len(declined) >= _DECLINED_SLACK:
            self._sweep_declined()
        after = OVERDUE * self._patience
        timer = None
        if after < math.inf and self._loop_deadline is not None and self._deadlines is not None:
            when = self._loop_deadline(after)
            timer = self._deadlines.loop.call_at(when, self._overdue, msg_id, after)
        declined[msg_id] = (asked, timer)

    def _overdue(self, msg_id: int, after: float) -> None:
        waiter = self._waiting.get(msg_id)
        declined, warn = self._declined, self._warn
        if waiter is None or waiter.future.done() or declined is None or warn is None:
            return
        if msg_id not in declined:
            return
        asked, _ = declined[msg_id]
        asked_class = asked.partition("(")[0]
        warn(
            "%s has waited %g s for the reply from %s: %s.get_intra_msg_reply returned None "
            "and no reply() followed (it waits up to its timeout, %g s)",
            type(waiter.request).__name__ + f" #{msg_id}",
            after,
            asked,
            asked_class,
            waiter.seconds,
        )

    def _sweep_declined(self) -> None:
        """Forgets the notes of requests no longer waiting, and disarms their timers."""
        declined, waiting = self._declined, self._waiting
        if declined is None:
            return
        for msg_id in [i for i in declined if i not in waiting or waiting[i].future.done()]:
            _, timer = declined.pop(msg_id)
            if timer is not None:
                timer.cancel()

    def unanswered(self) -> list[tuple[str, str]]:
        """The declined internal requests still waiting: ``(request class, asked layer)`` each."""
        self._sweep_declined()
        if not self._declined:
            return []
        waiting = self._waiting
        return [
            (type(waiting[msg_id].request).__name__, asked)
            for msg_id, (asked, _) in self._declined.items()
        ]

    def fail_peer(self, peer: RobotId, error: Callable[[str], Exception]) -> None:
        """Fails every external request waiting on robot ``peer`` (it left) with ``error(what)``."""
        for msg_id, waiter in list(self._waiting.items()):
            if waiter.external and waiter.peer == peer and not waiter.future.done():
                _remember(self._expired, msg_id)
                waiter.future.set_exception(error(waiter.what))

    def close(self) -> None:
        """The robot stopped: disarms the timer and fails every request still waiting."""
        if self._deadlines is not None:
            self._deadlines.cancel()
        if self._declined is not None:
            for _, timer in self._declined.values():
                if timer is not None:
                    timer.cancel()
            self._declined = None
        for waiter in self._waiting.values():
            if not waiter.future.done():
                waiter.future.set_exception(
                    RobotStateError(
                        f"{self._owner}: stopped while waiting for the reply from {waiter.what}"
                    )
                )
        self._waiting.clear()


def check_reply(
    answer: Message, expected: type[Message] | None, asked: Message, owner: str
) -> Message:
    """``answer``, if it is of the class the request ``asked`` asked for (``None``: any).

    Raises:
        UnexpectedReply: naming both classes (``owner`` names the asking layer).
    """
    if expected is None or isinstance(answer, expected):
        return answer
    raise UnexpectedReply(
        f"{owner}asked {type(asked).__name__} #{asked.msg_id} for a "
        f"{expected.__name__} reply, got a {type(answer).__name__}: {answer!r}",
        answer,
        expected,
    )
