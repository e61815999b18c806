"""A layer's inbox: a single-consumer message channel with an overflow policy.

``asyncio.Queue`` serves many getters and putters; a layer's inbox has exactly one
reader (the layer's task), so a deque and one waiter future do the same job with a
fraction of the bookkeeping. The reader drains every pending message in one pass
(a "batch"), so a burst costs one task wake-up, not one per message.

Overflow policy: internal messages (from neighbouring layers of the same robot) are
never dropped; external messages are refused with ``False`` once ``limit`` are
pending, and the caller counts the drop (a flood from the network cannot grow a
robot's memory without bound).
"""

from __future__ import annotations

import asyncio
from collections import deque
from typing import Final, Generic, TypeVar

__all__ = ["DEFAULT_EXTERNAL_LIMIT", "Channel"]

T = TypeVar("T")

DEFAULT_EXTERNAL_LIMIT: Final = 10_000
"""Pending messages above which external messages are dropped."""


class Channel(Generic[T]):
    """Many writers, one reader; unbounded for internal traffic, bounded for external."""

    __slots__ = ("_items", "_nudged", "_waiter", "limit")

    def __init__(self, limit: int = DEFAULT_EXTERNAL_LIMIT) -> None:
        self._items: deque[T] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self._nudged = False
        self.limit = limit

    def __len__(self) -> int:
        return len(self._items)

    def put(self, item: T) -> None:
        """Appends an item and wakes the reader; never blocks, never drops."""
        self._items.append(item)
        self._wake()

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
        """Appends an item unless ``limit`` items are pending; returns whether it did."""
        if len(self._items) >= self.limit:
            return False
        self.put(item)
        return True

    def pop(self) -> T:
        """The oldest item; the caller checks ``len()`` first (``IndexError`` if empty)."""
        return self._items.popleft()

    async def wait(self) -> None:
        """Returns when an item is pending or after a nudge (cancel the reader to stop it)."""
        while not self._items and not self._nudged:
            waiter = self._waiter = asyncio.get_running_loop().create_future()
            await waiter
        self._nudged = False
