"""What happens to an item: its events, one by one, and a read-only view of a ledger's list.

See :mod:`cas_async.sim._items` for the items and the ledger that records them.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Final, overload

from .._types import ItemId, RobotId

__all__ = ["EventsView", "ItemEvent", "ItemEventKind"]


class ItemEventKind(enum.Enum):
    """What happened to an item."""

    CREATED = "created"
    TRANSFERRED = "transferred"
    """Handed over: at once, or, with a latency, arrived in the receiver's hands."""
    RETIRED = "retired"
    SENT = "sent"
    """Left the giver's hands toward the receiver (with a latency)."""
    REFUSED = "refused"
    """Arrived in hands not held out to the giver: it travels back."""
    RETURNED = "returned"
    """A refused item is back in its giver's hands."""


@dataclass(frozen=True, slots=True)
class ItemEvent:
    """One change in an item's life.

    Attributes:
        t: the simulated instant it happened.
        kind: what happened.
        item: the item.
        robot: the creator, the giver, or the robot that retired it.
        receiver: the robot that received it (or was to): ``TRANSFERRED``, ``SENT``
            and ``REFUSED``; else ``None``.
    """

    t: float
    kind: ItemEventKind
    item: ItemId
    robot: RobotId
    receiver: RobotId | None = None

    @property
    def actor(self) -> RobotId:
        """The robot whose hands it happened in: the receiver's for an arrival or refusal."""
        if self.kind in _AT_RECEIVER and self.receiver is not None:
            return self.receiver
        return self.robot


_AT_RECEIVER: Final = frozenset({ItemEventKind.TRANSFERRED, ItemEventKind.REFUSED})


class EventsView(Sequence[ItemEvent]):
    """A read-only view of the ledger's event list (no copy per access)."""

    __slots__ = ("_events",)

    def __init__(self, events: list[ItemEvent]) -> None:
        self._events = events

    def __len__(self) -> int:
        return len(self._events)

    @overload
    def __getitem__(self, index: int) -> ItemEvent: ...
    @overload
    def __getitem__(self, index: slice) -> tuple[ItemEvent, ...]: ...
    def __getitem__(self, index: int | slice) -> ItemEvent | tuple[ItemEvent, ...]:
        if isinstance(index, slice):
            return tuple(self._events[index])
        return self._events[index]

    def __iter__(self) -> Iterator[ItemEvent]:
        return iter(self._events)

    def __repr__(self) -> str:
        return f"<{len(self._events)} item events>"
