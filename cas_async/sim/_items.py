"""Items that simulated robots carry, and a ledger that never loses nor duplicates one.

An item is an opaque object a robot holds: it is created in a robot's hands,
changes hands in atomic hand-overs, and is retired by the robot holding it.
The :class:`ItemLedger` records who holds what and every event, and checks the
conservation invariant: every item ever created is either retired or held by
exactly one robot. What an item stands for is the application's business.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import overload

from .._errors import SimulationError
from .._types import ItemId, RobotId

__all__ = ["ItemEvent", "ItemEventKind", "ItemLedger"]


class ItemEventKind(enum.Enum):
    """What happened to an item."""

    CREATED = "created"
    TRANSFERRED = "transferred"
    RETIRED = "retired"


@dataclass(frozen=True, slots=True)
class ItemEvent:
    """One change in an item's life.

    Attributes:
        t: the simulated instant it happened.
        kind: what happened.
        item: the item.
        robot: the creator, the giver, or the robot that retired it.
        receiver: the robot that received it (``TRANSFERRED`` only, else ``None``).
    """

    t: float
    kind: ItemEventKind
    item: ItemId
    robot: RobotId
    receiver: RobotId | None = None


class _Events(Sequence[ItemEvent]):
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


class ItemLedger:
    """Who holds which item, and every item event, in order.

    Two indexes are kept: item -> holder and robot -> items (in the order
    received). :meth:`check` verifies that they agree and that no item is lost
    or duplicated. Each item's events happen at non-decreasing instants.

    Args:
        checking: when ``True``, every mutating call ends with a cheap check of
            the item and robots it touched (not a full :meth:`check`).
    """

    def __init__(self, *, checking: bool = True) -> None:
        self._checking = checking
        self._holder: dict[ItemId, RobotId] = {}  # live items only
        # dict-as-ordered-set: O(1) removal, iteration in the order received
        self._held: dict[RobotId, dict[ItemId, None]] = {}
        self._histories: list[list[ItemEvent]] = []  # item i at index i - 1
        self._events: list[ItemEvent] = []
        self._retired = 0
        self._transfers = 0
        self._subscribers: list[Callable[[ItemEvent], None]] = []

    def __repr__(self) -> str:
        return (
            f"ItemLedger(created={self.created}, held={self.held}, retired={self._retired}, "
            f"transfers={self._transfers})"
        )

    # -- counts and queries -------------------------------------------------------------

    @property
    def created(self) -> int:
        """How many items were ever created."""
        return len(self._histories)

    @property
    def retired(self) -> int:
        """How many items were retired."""
        return self._retired

    @property
    def held(self) -> int:
        """How many items robots hold now (``created - retired``)."""
        return len(self._holder)

    @property
    def transfers(self) -> int:
        """How many hand-overs took place."""
        return self._transfers

    @property
    def events(self) -> Sequence[ItemEvent]:
        """Every event, in the order it happened (a read-only live view)."""
        return _Events(self._events)

    def holder(self, item: ItemId) -> RobotId | None:
        """The robot holding ``item`` now; ``None`` once it is retired.

        Raises:
            SimulationError: no such item was created.
        """
        self._history(item)
        return self._holder.get(item)

    def held_by(self, robot: RobotId) -> tuple[ItemId, ...]:
        """The items ``robot`` holds now, in the order it received them."""
        return tuple(self._held.get(robot, ()))

    def holders(self) -> tuple[RobotId, ...]:
        """Every robot that holds at least one item now (in no particular order)."""
        return tuple(self._held)  # a robot that holds nothing is not listed

    def history(self, item: ItemId) -> tuple[ItemEvent, ...]:
        """Every event of ``item``, oldest first (its first is ``CREATED``).

        Raises:
            SimulationError: no such item was created.
        """
        return tuple(self._history(item))

    def subscribe(self, callback: Callable[[ItemEvent], None]) -> None:
        """Calls ``callback(event)`` after every successful event, in subscription order.

        The event has happened by then: an exception from a callback propagates to
        the caller of the mutating method, but does not undo the event.
        """
        self._subscribers.append(callback)

    # -- events -------------------------------------------------------------------------

    def create(self, holder: RobotId, t: float) -> ItemId:
        """Creates a new item in ``holder``'s hands at instant ``t`` and returns its id.

        Raises:
            SimulationError: ``t`` is not finite.
        """
        _check_time(t, f"creating an item for robot {holder}")
        item = len(self._histories) + 1
        self._histories.append([])
        self._holder[item] = holder
        self._held.setdefault(holder, {})[item] = None
        self._record(ItemEvent(t, ItemEventKind.CREATED, item, holder), holder)
        return item

    def transfer(self, item: ItemId, giver: RobotId, receiver: RobotId, t: float) -> None:
        """Hands ``item`` from ``giver`` to ``receiver`` at instant ``t``, atomically.

        Raises:
            SimulationError: the item is unknown or retired, ``giver`` does not hold
                it, ``receiver`` is ``giver``, or ``t`` is not finite or precedes the
                item's previous event. Nothing changes then.
        """
        action = f"robot {giver} handing item {item} to robot {receiver}"
        self._check_event(item, giver, t, action)
        if receiver == giver:
            raise SimulationError(f"{action}: a robot cannot hand an item to itself")
        # Every check is done: from here on nothing can fail half-way.
        self._drop(item, giver)
        self._holder[item] = receiver
        self._held.setdefault(receiver, {})[item] = None
        self._transfers += 1
        self._record(
            ItemEvent(t, ItemEventKind.TRANSFERRED, item, giver, receiver), giver, receiver
        )

    def retire(self, item: ItemId, holder: RobotId, t: float) -> None:
        """Retires ``item``, held by ``holder``, at instant ``t``: nobody holds it any more.

        Raises:
            SimulationError: the item is unknown or retired already, ``holder`` does
                not hold it, or ``t`` is not finite or precedes the item's previous
                event. Nothing changes then.
        """
        self._check_event(item, holder, t, f"robot {holder} retiring item {item}")
        self._drop(item, holder)
        del self._holder[item]
        self._retired += 1
        self._record(ItemEvent(t, ItemEventKind.RETIRED, item, holder), holder)

    # -- the invariant ------------------------------------------------------------------

    def check(self) -> None:
        """Verifies that no item was lost or duplicated, in O(items).

        Every created item is either retired (and nobody holds it) or held by
        exactly one robot, and the item -> holder and robot -> items indexes agree.

        Raises:
            SimulationError: describing the first violation found.
        """
        live = 0
        for item, history in enumerate(self._histories, start=1):
            if history[-1].kind is ItemEventKind.RETIRED:
                if item in self._holder:
                    raise SimulationError(
                        f"item {item} was retired but robot {self._holder[item]} still holds it"
                    )
            else:
                live += 1
                self._check_held(item)
        listed = 0
        for robot, items in self._held.items():
            for item in items:
                listed += 1
                if self._holder.get(item) != robot:
                    raise SimulationError(
                        f"robot {robot} lists item {item}, whose holder is "
                        f"{self._describe_holder(item)}: the item is duplicated or stale"
                    )
        if listed != live or len(self._holder) != live:
            raise SimulationError(
                f"{live} items are live, but the robots list {listed} and the item index "
                f"has {len(self._holder)}: an unknown item is held"
            )
        if live + self._retired != len(self._histories):
            raise SimulationError(
                f"{len(self._histories)} items were created, but {live} are held and "
                f"{self._retired} counted as retired"
            )

    # -- internals ----------------------------------------------------------------------

    def _history(self, item: ItemId) -> list[ItemEvent]:
        if isinstance(item, int) and 1 <= item <= len(self._histories):
            return self._histories[item - 1]
        raise SimulationError(f"item {item!r} is unknown: {self.created} items were created")

    def _check_event(self, item: ItemId, robot: RobotId, t: float, action: str) -> None:
        """The preconditions shared by transfer and retire."""
        history = self._history(item)
        last = history[-1]
        if last.kind is ItemEventKind.RETIRED:
            raise SimulationError(f"{action}: item {item} was retired at {last.t!r}")
        holder = self._holder.get(item)
        if holder != robot:
            raise SimulationError(f"{action}: robot {robot} does not hold it (robot {holder} does)")
        if item not in self._held.get(robot, ()):
            # Only a corrupted ledger gets here; refusing keeps the event atomic.
            raise SimulationError(
                f"{action}: the ledger is corrupted: robot {robot} does not list it"
            )
        _check_time(t, action)
        if t < last.t:
            raise SimulationError(
                f"{action} at {t!r}: the item's previous event was at {last.t!r}, "
                "and time does not go backwards"
            )

    def _drop(self, item: ItemId, robot: RobotId) -> None:
        items = self._held[robot]
        del items[item]
        if not items:
            del self._held[robot]  # robots that hold nothing are not listed

    def _record(self, event: ItemEvent, *touched: RobotId) -> None:
        self._histories[event.item - 1].append(event)
        self._events.append(event)
        if self._checking:
            self._check_local(event.item, touched)
        for callback in self._subscribers:
            callback(event)

    def _check_local(self, item: ItemId, robots: tuple[RobotId, ...]) -> None:
        """The invariant restricted to one item and the robots an event touched."""
        retired = self._histories[item - 1][-1].kind is ItemEventKind.RETIRED
        if retired and item in self._holder:
            raise SimulationError(f"item {item} was retired but is still held")
        if not retired:
            self._check_held(item)
        for robot in robots:
            listed = item in self._held.get(robot, ())
            if listed != (self._holder.get(item) == robot):
                raise SimulationError(
                    f"robot {robot} {'lists' if listed else 'does not list'} item {item}, "
                    f"whose holder is {self._describe_holder(item)}"
                )

    def _check_held(self, item: ItemId) -> None:
        holder = self._holder.get(item)
        if holder is None:
            raise SimulationError(f"item {item} is lost: it was not retired but nobody holds it")
        if item not in self._held.get(holder, ()):
            raise SimulationError(
                f"item {item} is held by robot {holder}, but robot {holder} does not list it"
            )

    def _describe_holder(self, item: ItemId) -> str:
        holder = self._holder.get(item)
        return "nobody" if holder is None else f"robot {holder}"


def _check_time(t: float, action: str) -> None:
    if not math.isfinite(t):
        raise SimulationError(f"{action}: t must be a finite number, got {t!r}")
