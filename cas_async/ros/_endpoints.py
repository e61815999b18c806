"""A link's publishers and subscriptions: what one ROS topic endpoint does with its samples.

A :class:`RosPublisher` encodes plain values to CDR and puts them under the topic's
key with rmw_zenoh's attachment (its own sequence number from 1, the time, its GID).
A :class:`RosSubscription` is an async iterator of decoded messages: Zenoh's thread
hands each sample to the link's :class:`~cas_async.transport.zenoh._thread_inbox.ThreadInbox`,
and the loop decodes it here. Like an rmw_zenoh subscription it keeps the last
``depth`` messages (``KEEP_LAST``): a reader that falls behind loses the oldest,
counted as ``overflow``. A sample is dropped and counted by reason when it has no
or a malformed attachment (rmw_zenoh drops those too), is longer than the
subscription's ``max_bytes`` (``oversize``: measured on Zenoh's thread, before it is
copied), is not the type's CDR (``malformed_cdr``) or holds a number that is not
finite (``non_finite``: a NaN pose from a glitching driver, or from anyone on the
robot's router): only values a layer can use reach it. Each reason is logged at its
1st, 10th, 100th... drop: nothing is lost silently, and a flood costs a few lines.

Per publisher (GID) the subscription keeps the last sequence number, to count what
never arrived (``lost``), for the :data:`SEQUENCE_PEERS` publishers heard from
last; a jump of more than :data:`SEQUENCE_JUMP` is a publisher that restarted (or
a forged number), counted in ``sequence_jumps``, not as lost samples.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections import OrderedDict, deque
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, Final

from .. import RobotStateError
from ._attachment import Attachment
from ._graph import GraphEntity, entity_gid

if TYPE_CHECKING:
    from ._message_types import RosType

__all__ = [
    "DEFAULT_MAX_BYTES",
    "SEQUENCE_JUMP",
    "SEQUENCE_PEERS",
    "RosPublisher",
    "RosSubscription",
    "all_finite",
    "is_power_of_ten",
]

DEFAULT_MAX_BYTES: Final = 1024 * 1024
"""Bytes of a sample, at most, for a type with no bound of its own (an unbounded string)."""
SEQUENCE_PEERS: Final = 256
"""Publishers whose last sequence number a subscription keeps (the latest heard from)."""
SEQUENCE_JUMP: Final = 10_000
"""A sequence number this far past the last is a restart (or a forgery), not lost samples."""

_log = logging.getLogger("cas_async.ros")


def is_power_of_ten(n: int) -> bool:
    """Whether ``n`` is 1, 10, 100, ...: when the n-th of a kind of event is logged."""
    while n >= 10 and n % 10 == 0:
        n //= 10
    return n == 1


def all_finite(value: Any) -> bool:
    """Whether every float in a decoded message (dicts and lists of them) is finite."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(all_finite(item) for item in value.values())
    if isinstance(value, list):
        return all(all_finite(item) for item in value)
    return True


class RosPublisher:
    """Publishes plain values on one topic (``link.publisher(topic, ros_type)``).

    Attributes:
        topic: the fully qualified topic name.
        ros_type: the message type.
        entity: the publisher as the ROS graph sees it (its token).
        published: samples put so far (the last sequence number).
    """

    def __init__(
        self,
        entity: GraphEntity,
        ros_type: RosType,
        publisher: Any,
        token: Any,
        clock_ns: Callable[[], int],
    ) -> None:
        self.topic = entity.topic
        self.ros_type = ros_type
        self.entity = entity
        self.published = 0
        self._gid = entity_gid(entity.token())
        self._publisher = publisher
        self._token = token
        self._clock_ns = clock_ns
        self._closed = False

    def publish(self, value: Mapping[str, Any]) -> None:
        """Encodes ``value`` and puts it, with its attachment.

        Raises:
            EncodeError: ``value`` does not fit the type (the message names the field).
            RobotStateError: the publisher or its link is closed.
        """
        if self._closed:
            raise RobotStateError(f"ROS publisher on {self.topic} is closed")
        payload = self.ros_type.encode(value)
        self.published += 1
        attachment = Attachment(self.published, self._clock_ns(), self._gid).to_bytes()
        self._publisher.put(payload, attachment=attachment)

    @property
    def matched(self) -> bool:
        """Whether some subscriber of the topic's key is known to the session now."""
        if self._closed:
            return False
        return bool(self._publisher.matching_status.matching)

    def close(self) -> None:
        """Withdraws the publisher and its token; idempotent."""
        if self._closed:
            return
        self._closed = True
        for declared in (self._token, self._publisher):
            with contextlib.suppress(Exception):
                declared.undeclare()

    def __repr__(self) -> str:
        return f"RosPublisher({self.topic!r}, {self.ros_type.name}, {self.published} published)"


class RosSubscription:
    """Decoded messages of one topic, in order: ``async for msg in subscription``.

    Attributes:
        topic: the fully qualified topic name.
        ros_type: the message type.
        entity: the subscription as the ROS graph sees it (its token).
        depth: how many messages wait for the reader at most.
        max_bytes: the longest sample taken, in bytes (longer: dropped, ``oversize``).
        finite: whether a message with a NaN or an infinity is dropped (``non_finite``).
        latest: the last message decoded (``None`` before the first), read or not.
        received: samples decoded and queued.
        lost: samples the publishers' sequence numbers say never arrived.
        sequence_jumps: sequence numbers far past a publisher's last (restarts, forgeries).
        dropped: samples dropped, by reason (``no_attachment``, ``bad_attachment``,
            ``oversize``, ``malformed_cdr``, ``non_finite``, ``overflow``, and what
            a reader counts with :meth:`drop`).
    """

    def __init__(
        self,
        entity: GraphEntity,
        ros_type: RosType,
        depth: int,
        *,
        max_bytes: int = DEFAULT_MAX_BYTES,
        finite: bool = True,
    ) -> None:
        self.topic = entity.topic
        self.ros_type = ros_type
        self.entity = entity
        self.depth = depth
        self.max_bytes = max_bytes
        self.finite = finite
        self.latest: dict[str, Any] | None = None
        self.received = 0
        self.lost = 0
        self.sequence_jumps = 0
        self.dropped: dict[str, int] = {}
        self._queue: deque[dict[str, Any]] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self._last_sequence: OrderedDict[bytes, int] = OrderedDict()
        self._declared: list[Any] = []
        self._closed = False

    def attach(self, *declared: Any) -> None:
        """Called by the link: the Zenoh subscriber and token this subscription owns."""
        self._declared.extend(declared)

    def taken(self, size: int) -> bool:
        """Whether a sample of ``size`` bytes is taken (called on Zenoh's thread: no state)."""
        return size <= self.max_bytes

    def refuse_oversize(self, size: int) -> None:
        """Called on the loop for a sample :meth:`taken` refused: counts it."""
        if not self._closed:
            self.drop("oversize", f"{size:,} bytes, more than the {self.max_bytes:,} taken")

    def deliver(self, payload: bytes, attachment: bytes | None) -> None:
        """Called on the loop with one sample from Zenoh: decodes and queues it, or drops it."""
        if self._closed:
            return
        if attachment is None:
            self.drop("no_attachment", "a sample without rmw_zenoh's attachment")
            return
        try:
            info = Attachment.from_bytes(attachment)
        except ValueError as exc:
            self.drop("bad_attachment", str(exc))
            return
        if len(payload) > self.max_bytes:
            self.drop("oversize", f"{len(payload):,} bytes, more than the {self.max_bytes:,} taken")
            return
        try:
            message = self.ros_type.decode(payload)
        except Exception as exc:  # rosbags' SerdeError and whatever malformed bytes cause
            self.drop("malformed_cdr", f"{len(payload)} bytes: {str(exc)[:200]}")
            return
        if self.finite and not all_finite(message):
            self.drop("non_finite", "a number that is not finite (NaN or infinity)")
            return
        self._count_sequence(info.gid, info.sequence)
        self.received += 1
        self.latest = message
        if len(self._queue) >= self.depth:
            self._queue.popleft()
            self.drop("overflow", f"the reader is more than {self.depth} messages behind")
        self._queue.append(message)
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def _count_sequence(self, gid: bytes, sequence: int) -> None:
        last = self._last_sequence.pop(gid, None)
        if last is not None and sequence > last + 1:
            if sequence - last > SEQUENCE_JUMP:
                self.sequence_jumps += 1
            else:
                self.lost += sequence - last - 1
        self._last_sequence[gid] = sequence  # the newest last: the oldest go first
        if len(self._last_sequence) > SEQUENCE_PEERS:
            self._last_sequence.popitem(last=False)

    def drop(self, reason: str, detail: str) -> None:
        """Counts a message dropped for ``reason`` (logged at the 1st, 10th, 100th... of it).

        The subscription counts its own drops; a reader that cannot use a message it
        received (a pose out of any range) counts it here too.
        """
        count = self.dropped[reason] = self.dropped.get(reason, 0) + 1
        if is_power_of_ten(count):
            _log.warning(
                "ROS subscription %s dropped %s (%s, %d so far): %s",
                self.topic,
                reason,
                self.ros_type.name,
                count,
                detail,
            )

    async def receive(self) -> dict[str, Any]:
        """The next message (waits for it).

        Raises:
            RobotStateError: the subscription or its link is closed.
        """
        while not self._queue:
            if self._closed:
                raise RobotStateError(f"ROS subscription on {self.topic} is closed")
            self._waiter = asyncio.get_running_loop().create_future()
            try:
                await self._waiter
            finally:
                self._waiter = None
        return self._queue.popleft()

    def clear(self) -> int:
        """Discards the messages waiting (a reader that wants only fresh ones); how many."""
        count = len(self._queue)
        self._queue.clear()
        return count

    def __aiter__(self) -> RosSubscription:
        return self

    async def __anext__(self) -> dict[str, Any]:
        try:
            return await self.receive()
        except RobotStateError:
            raise StopAsyncIteration from None

    def close(self) -> None:
        """Withdraws the subscription and its token; a reader waiting ends. Idempotent."""
        if self._closed:
            return
        self._closed = True
        declared, self._declared = self._declared, []
        for item in declared:
            with contextlib.suppress(Exception):
                item.undeclare()
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def __repr__(self) -> str:
        return (
            f"RosSubscription({self.topic!r}, {self.ros_type.name}, {self.received} received, "
            f"dropped {self.dropped})"
        )
