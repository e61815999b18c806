"""A layer's inbox: a single-consumer message channel with a named overflow policy.

``asyncio.Queue`` serves many getters and putters; a layer's inbox has exactly one
reader (the layer's task), so a deque and one waiter future do the same job with a
fraction of the bookkeeping. The reader drains every pending message in one pass
(a "batch"), so a burst costs one task wake-up, not one per message.

Overflow policy, at ``limit`` pending messages (the inbox is *full*):

* external messages (from the network) are refused by :meth:`Channel.offer`, and
  the robot counts the drop as ``queue_full``: a flood from other robots cannot
  grow a robot's memory without bound;
* internal messages (from this robot's own layers) are never dropped: :meth:`put`
  always appends and reports that the inbox is full, and the sending layer then
  waits in its loop (:meth:`room`) until the inbox has drained to half the limit
  before it handles its next message. That is back-pressure: a fast producer
  slows to its consumer's pace instead of piling messages up.
"""

from __future__ import annotations

import asyncio
from collections import deque
from typing import Final, Generic, TypeVar

__all__ = ["DEFAULT_QUEUE_LIMIT", "Channel"]

T = TypeVar("T")

DEFAULT_QUEUE_LIMIT: Final = 10_000
"""Pending messages at which an inbox is full."""


class Channel(Generic[T]):
    """Many writers, one reader, bounded by ``limit`` (see the module docs)."""

    __slots__ = ("_items", "_low", "_nudged", "_room_waiters", "_waiter", "limit")

    def __init__(self, limit: int = DEFAULT_QUEUE_LIMIT) -> None:
        self._items: deque[T] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self._room_waiters: list[asyncio.Future[None]] = []
        self._nudged = False
        self.limit = limit
        self._low = limit // 2  # back-pressure lifts here: not at every single pop

    def __len__(self) -> int:
        return len(self._items)

    def put(self, item: T) -> bool:
        """Appends an item and wakes the reader; never drops. Returns whether it is full now."""
        items = self._items
        items.append(item)
        waiter = self._waiter  # _wake(), inlined: this is every message's hop
        if waiter is not None:
            self._waiter = None
            if not waiter.done():
                waiter.set_result(None)
        return len(items) >= self.limit

    def nudge(self) -> None:
        """Wakes the reader once even though nothing is pending (a timer went off)."""
        self._nudged = True
        self._wake()

    def _wake(self) -> None:
        waiter = self._waiter
        if waiter is not None:
            self._waiter = None
            if not waiter.done():
                waiter.set_result(None)

    def offer(self, item: T) -> bool:
        """Appends an item unless the channel is full; returns whether it did."""
        items = self._items
        if len(items) >= self.limit:
            return False
        items.append(item)
        waiter = self._waiter  # _wake(), inlined: every external message takes this hop
        if waiter is not None:
            self._waiter = None
            if not waiter.done():
                waiter.set_result(None)
        return True

    def pop(self) -> T | None:
        """The oldest item, or ``None`` when nothing is pending."""
        items = self._items
        if not items:
            return None
        item = items.popleft()
        if self._room_waiters and len(items) <= self._low:
            self.release_room_waiters()
        return item

    async def wait(self) -> None:
        """Returns when an item is pending or after a nudge (cancel the reader to stop it)."""
        while not self._items and not self._nudged:
            waiter = self._waiter = asyncio.get_running_loop().create_future()
            await waiter
        self._nudged = False

    @property
    def crowded(self) -> bool:
        """Whether more than half the limit is pending (senders held back wait for less)."""
        return len(self._items) > self._low

    async def room(self) -> None:
        """Waits until at most half the limit is pending, or :meth:`release_room_waiters`."""
        waiter = asyncio.get_running_loop().create_future()
        self._room_waiters.append(waiter)
        await waiter

    def release_room_waiters(self) -> None:
        """Wakes every sender waiting in :meth:`room`, to look again at why it waits."""
        waiters, self._room_waiters = self._room_waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(None)
