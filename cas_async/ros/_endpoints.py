"""A link's publishers and subscriptions: what one ROS topic endpoint does with its samples.

A :class:`RosPublisher` encodes plain values to CDR and puts them under the topic's
key with rmw_zenoh's attachment (its own sequence number from 1, the time, its GID).
A :class:`RosSubscription` is an async iterator of decoded messages: Zenoh's thread
hands each sample to the link's :class:`~cas_async.transport.zenoh._thread_inbox.ThreadInbox`,
and the loop decodes it here. Like an rmw_zenoh subscription it keeps the last
``depth`` messages (``KEEP_LAST``): a reader that falls behind loses the oldest,
counted as ``overflow``. A sample with no or a malformed attachment (rmw_zenoh drops
those too) or with bytes that are not the type's CDR is dropped and counted, and the
first drop of each reason is logged: nothing is lost silently.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections import deque
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from .. import RobotStateError
from ._attachment import Attachment
from ._graph import GraphEntity, entity_gid

if TYPE_CHECKING:
    from ._message_types import RosType

__all__ = ["RosPublisher", "RosSubscription"]

_log = logging.getLogger("cas_async.ros")


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
        latest: the last message decoded (``None`` before the first), read or not.
        received: samples decoded and queued.
        lost: samples the publishers' sequence numbers say never arrived.
        dropped: samples dropped, by reason (``no_attachment``, ``bad_attachment``,
            ``malformed_cdr``, ``overflow``).
    """

    def __init__(self, entity: GraphEntity, ros_type: RosType, depth: int) -> None:
        self.topic = entity.topic
        self.ros_type = ros_type
        self.entity = entity
        self.depth = depth
        self.latest: dict[str, Any] | None = None
        self.received = 0
        self.lost = 0
        self.dropped: dict[str, int] = {}
        self._queue: deque[dict[str, Any]] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self._last_sequence: dict[bytes, int] = {}
        self._declared: list[Any] = []
        self._closed = False

    def attach(self, *declared: Any) -> None:
        """Called by the link: the Zenoh subscriber and token this subscription owns."""
        self._declared.extend(declared)

    def deliver(self, payload: bytes, attachment: bytes | None) -> None:
        """Called on the loop with one sample from Zenoh: decodes and queues it, or drops it."""
        if self._closed:
            return
        if attachment is None:
            self._drop("no_attachment", "a sample without rmw_zenoh's attachment")
            return
        try:
            info = Attachment.from_bytes(attachment)
        except ValueError as exc:
            self._drop("bad_attachment", str(exc))
            return
        try:
            message = self.ros_type.decode(payload)
        except Exception as exc:  # rosbags' SerdeError and whatever malformed bytes cause
            self._drop("malformed_cdr", f"{len(payload)} bytes: {exc}")
            return
        last = self._last_sequence.get(info.gid)
        if last is not None and info.sequence > last + 1:
            self.lost += info.sequence - last - 1
        self._last_sequence[info.gid] = info.sequence
        self.received += 1
        self.latest = message
        if len(self._queue) >= self.depth:
            self._queue.popleft()
            self._drop("overflow", f"the reader is more than {self.depth} messages behind")
        self._queue.append(message)
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def _drop(self, reason: str, detail: str) -> None:
        count = self.dropped[reason] = self.dropped.get(reason, 0) + 1
        if count == 1:
            _log.warning(
                "ROS subscription %s dropped %s (%s): %s",
                self.topic,
                reason,
                self.ros_type.name,
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
