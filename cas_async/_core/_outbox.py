"""A robot's outgoing external messages: stamped, encoded, sent and counted in one place.

:class:`Outbox` is the twin of :class:`~cas_async._core._reception.Reception`: every
message a layer sends to another robot (``send``, ``resend``, ``broadcast``,
``reply`` and each attempt of ``request``) leaves the robot here. The outbox owns
what sending needs: the robot's message ids (internal messages take theirs from
it too, so ids are unique per robot), the wire codec, the transport endpoint,
and the replies kept for requests that may be sent again.

Before the robot starts, the outbox holds stand-ins: an endpoint that explains
that the robot has no transport (:class:`~cas_async._core._unconnected.Unconnected`)
and a codec that explains that the robot has not started. Nothing on the send
path checks for ``None``.

Ownership: once sent, a message belongs to the runtime, which writes its header.
:func:`owned` gives the object to stamp: the message itself the first time, a
copy when it was sent before, so a message still travelling never changes.
"""

from __future__ import annotations

import copy
import itertools
from collections.abc import Callable, Iterable, Iterator
from typing import Final, NoReturn, Protocol, final

from .._errors import RobotStateError, UnknownRobotError
from .._types import Address, Level, RobotId
from .._wire._message import Message, MsgType
from .._wire._payloads import WireCodec
from ._counters import LayerCounters, count_sent_external
from ._dedup import ReplyCache
from ._logs import DropLog
from ._transport_contract import Endpoint
from ._unconnected import Unconnected

__all__ = ["Outbox", "Sender", "owned"]

_NEGOTIATION: Final = MsgType.NEGOTIATION


def owned(msg: Message) -> Message:
    """The object to stamp and send: ``msg`` the first time, a copy if it was sent before."""
    return msg if msg.msg_id == 0 else copy.copy(msg)


class Sender(Protocol):
    """The layer a message leaves from, as the outbox sees it (a layer's runtime)."""

    @property
    def live(self) -> bool:
        """Whether the robot runs (the layer may send)."""

    @property
    def level(self) -> Level:
        """The layer's level: external messages go to the same level."""

    @property
    def counters(self) -> LayerCounters:
        """Where what it sends is counted."""

    def check_live(self) -> None:
        """Raises ``RobotStateError``, naming why the layer may not send."""

    def violation(self, reason: str, msg: Message) -> None:
        """Counts a message the layer sent against a rule."""


def _no_time() -> float:
    return 0.0


@final
class _NotStarted:
    """The wire codec of a robot that has not started: every use says so."""

    passes_objects = False

    def __init__(self, robot_id: RobotId) -> None:
        self._robot_id = robot_id

    def _refuse(self) -> NoReturn:
        raise RobotStateError(f"robot {self._robot_id} has not started: it has no codec yet")

    @property
    def fingerprint(self) -> int:
        """Raises ``RobotStateError``."""
        self._refuse()

    def encode(self, msg: Message) -> bytes:
        """Raises ``RobotStateError``."""
        self._refuse()

    def decode(self, data: bytes) -> Message:
        """Raises ``RobotStateError``."""
        self._refuse()


@final
class Outbox:
    """Sends one robot's external messages; see the module docs.

    Args:
        robot_id: the robot whose header every message carries.
        drops: counts a reply that could not be delivered (its asker left).

    Attributes:
        replies_resent: kept replies sent again to a repeated request.
    """

    __slots__ = (
        "_codec",
        "_drops",
        "_endpoint",
        "_ids",
        "_now",
        "_replies",
        "replies_resent",
        "robot_id",
    )

    def __init__(self, robot_id: RobotId, drops: DropLog) -> None:
        self.robot_id = robot_id
        self._drops = drops
        self._ids: Iterator[int] = itertools.count(1)
        self._codec: WireCodec = _NotStarted(robot_id)
        self._endpoint: Endpoint = Unconnected(robot_id)
        self._replies = ReplyCache()
        self._now: Callable[[], float] = _no_time
        self.replies_resent = 0

    # -- lifecycle ---------------------------------------------------------------------

    def connect(
        self,
        codec: WireCodec,
        endpoint: Endpoint | None,
        first_id: int,
        *,
        now: Callable[[], float],
        replies: ReplyCache,
    ) -> None:
        """Sends with ``codec`` through ``endpoint`` (``None``: none), ids from ``first_id``.

        Ids only grow, also across restarts of a robot: receivers tell a re-sent or
        duplicated message from a new one by (robot id, message id). ``replies``
        keeps the replies sent, dated by ``now()``, for repeated requests.
        """
        self._codec = codec
        if endpoint is not None:
            self._endpoint = endpoint
        self._ids = itertools.count(first_id)
        self._now = now
        self._replies = replies

    def next_id(self) -> int:
        """The first message id not used yet (taking it: call when the robot stops)."""
        return next(self._ids)

    def close(self) -> None:
        """Closes the endpoint; sending then raises ``RobotStateError`` (idempotent)."""
        self._endpoint.close()

    def follow_membership(self, follow: bool) -> None:
        """Whether the robot hears of others joining and leaving (while its layers run)."""
        self._endpoint.follow_membership(follow)

    @property
    def codec(self) -> WireCodec:
        """The wire codec (a stand-in that raises before the robot starts)."""
        return self._codec

    @property
    def address(self) -> Address:
        """Where other robots reach this one (``None`` without a transport)."""
        return self._endpoint.address

    def knows(self, robot_id: RobotId) -> bool:
        """Whether a message to ``robot_id`` (or a reply to it) can be sent."""
        return self._endpoint.knows(robot_id)

    # -- stamping ----------------------------------------------------------------------

    def stamp(self, msg: Message, src: Level, dst: Level, corr_id: int = 0) -> None:
        """Writes the header of a message this robot sends (internal ones too)."""
        msg.msg_id = next(self._ids)
        msg.robot_id = self.robot_id
        msg.src_layer = src
        msg.dst_layer = dst
        msg.corr_id = corr_id

    # -- sending -------------------------------------------------------------------------

    def send(self, sender: Sender, robot_id: RobotId, msg: Message) -> None:
        """Stamps, encodes and sends ``msg`` from layer ``sender`` to robot ``robot_id``.

        No copy is needed when the message is encoded before this returns; a codec
        that passes objects sends a copy of one sent before.

        A robot the transport does not know (it left, or never joined) is not an
        error: the message is dropped and counted as ``unknown_robot``.

        Raises:
            RobotStateError: the robot does not run.
            EncodeError: the message cannot be encoded.
            ConfigurationError: the robot has no transport.
        """
        if not sender.live:
            sender.check_live()
        if robot_id == self.robot_id:
            sender.violation("to_own_robot", msg)
            return
        codec = self._codec
        if codec.passes_objects:
            msg = owned(msg)
        level = sender.level
        self.stamp(msg, level, level)
        self.transmit(sender.counters, robot_id, codec.encode(msg), msg.__class__)

    def resend(self, counters: LayerCounters, robot_id: RobotId, msg: Message) -> None:
        """Sends a message already stamped by this robot again, unchanged (same id)."""
        self.transmit(counters, robot_id, self._codec.encode(msg), msg.__class__)

    def request(self, level: Level, msg: Message) -> bytes:
        """Stamps ``msg`` (already owned) as a NEGOTIATION from ``level``; returns its datagram.

        Each attempt then goes out through :meth:`transmit`: the same bytes, so the
        other robot handles the request once however often it is sent.
        """
        msg.msg_type = _NEGOTIATION
        self.stamp(msg, level, level)
        return self._codec.encode(msg)

    def broadcast(
        self,
        counters: LayerCounters,
        level: Level,
        msg: Message,
        robots: Iterable[RobotId] | None,
    ) -> None:
        """Sends one message to several robots (every known one when ``robots`` is ``None``).

        Encoded once; with a codec that passes objects, each receiver gets its own
        copy. A robot the transport does not know is counted as ``unknown_robot``.
        """
        codec, endpoint = self._codec, self._endpoint
        if codec.passes_objects:
            msg = owned(msg)  # receivers may still hold it
        self.stamp(msg, level, level)
        data = codec.encode(msg)
        first = True
        for robot_id in endpoint.peers() if robots is None else robots:
            if robot_id == self.robot_id:
                continue
            if not first and codec.passes_objects:  # each receiver gets a message of its own
                data = codec.encode(copy.copy(msg))
            first = False
            self.transmit(counters, robot_id, data, msg.__class__)

    def reply(
        self,
        counters: LayerCounters,
        level: Level,
        asker: RobotId,
        request_id: int,
        response: Message,
    ) -> None:
        """Answers request ``request_id`` of robot ``asker``, and keeps the reply.

        A repetition of that request (its asker did not get this reply) is answered
        with the kept bytes (:meth:`resend_reply`). An asker that left meanwhile is
        a dropped reply (``reply_undeliverable``), not an error.
        """
        if response.msg_id:  # sent before (or the request itself): a copy
            response = copy.copy(response)
        self.stamp(response, level, level, request_id)
        data = self._codec.encode(response)
        self._replies.keep(asker, request_id, data, self._now())
        self.transmit(counters, asker, data, response.__class__, unknown="reply_undeliverable")

    def resend_reply(self, asker: RobotId, request_id: int) -> None:
        """Answers a repeated request with the reply kept for it, if any (not counted as sent)."""
        data = self._replies.get(asker, request_id)
        if data is None:
            return
        self.replies_resent += 1
        try:
            self._endpoint.send(asker, data)
        except UnknownRobotError as exc:
            self._drops.drop("reply_undeliverable", "%s", exc)

    def transmit(
        self,
        counters: LayerCounters,
        robot_id: RobotId,
        data: bytes,
        kind: type[Message],
        *,
        unknown: str = "unknown_robot",
    ) -> bool:
        """Sends an encoded message of class ``kind`` and counts it; whether it went.

        Every external message leaves the robot here: each ``send``, each attempt
        of a request, a reply, a resend, each copy of a broadcast. A robot the
        transport does not know is a drop counted under ``unknown`` (``False``),
        never an error.
        """
        try:
            self._endpoint.send(robot_id, data)
        except UnknownRobotError as exc:
            self._drops.drop(unknown, "%s: %s", kind.__name__, exc)
            return False
        count_sent_external(counters, kind)
        return True
