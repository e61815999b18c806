"""Items that simulated robots carry, and a ledger that never loses nor duplicates one.

An item is an opaque object a robot holds: it is created in a robot's hands,
changes hands in atomic hand-overs, and is retired by the robot holding it.
The :class:`ItemLedger` records who holds what and every event, and checks the
conservation invariant: every item ever created is either retired or held by
exactly one robot. What an item stands for is the application's business.

In a simulation with a network latency a hand-over takes time too: the item
leaves the giver (``SENT``), is in nobody's hands while it travels, and arrives
in the receiver's (``TRANSFERRED``), or, refused there (``REFUSED``), travels back
and is the giver's again (``RETURNED``). The invariant then reads: every item is
retired, held by exactly one robot, or on its way to exactly one.

A ledger may see only part of the items (``partial``): in a simulation spread over
processes each process keeps the items of its own robots, an item arriving from
another process joins it, and an item handed to one leaves it. Item ids are then
made by their creator (``ids_by_creator``), so that they do not depend on which
robots share a process. The whole story is kept by whoever gathers every
process's events (:meth:`apply` in their order, see :meth:`ItemEvent.order`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Final

from .._errors import SimulationError
from .._types import ItemId, RobotId
from ._item_events import EventsView, ItemEvent, ItemEventKind

__all__ = ["ID_SPAN", "ItemLedger"]


ID_SPAN: Final = 2**32
"""Items one robot may create, with ids made by their creator: ``robot * ID_SPAN + n``."""


class ItemLedger:
    """Who holds which item, and every item event, in order.

    Two indexes are kept: item -> holder and robot -> items (in the order
    received), and the items on their way. :meth:`check` verifies that they agree
    and that no item is lost or duplicated. Each item's events happen at
    non-decreasing instants.

    Args:
        checking: when ``True``, every mutating call ends with a cheap check of
            the item and robots it touched (not a full :meth:`check`).
        ids_by_creator: make item ids ``robot * ID_SPAN + n`` (the creator's
            ``n``-th item, from 1) instead of counting every item from 1.
        partial: the ledger holds the items of some robots only (see the module
            docs): an item may arrive that it never saw, and leave to another ledger.
    """

    def __init__(
        self, *, checking: bool = True, ids_by_creator: bool = False, partial: bool = False
    ) -> None:
        self._checking = checking
        self._by_creator = ids_by_creator or partial
        self._partial = partial
        self._holder: dict[ItemId, RobotId] = {}  # items held now
        self._transit: dict[ItemId, tuple[RobotId, RobotId]] = {}  # on the way: from, to
        # dict-as-ordered-set: O(1) removal, iteration in the order received
        self._held: dict[RobotId, dict[ItemId, None]] = {}
        self._histories: dict[ItemId, list[ItemEvent]] = {}
        self._made: dict[RobotId, int] = {}  # items each robot created (ids by creator)
        self._events: list[ItemEvent] = []
        self._created = 0
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
        """How many items were ever created (here)."""
        return self._created

    @property
    def retired(self) -> int:
        """How many items were retired (here)."""
        return self._retired

    @property
    def held(self) -> int:
        """How many items robots hold now (``created - retired``, less those on their way)."""
        return len(self._holder)

    @property
    def in_transit(self) -> int:
        """How many items are on their way from one robot's hands to another's."""
        return len(self._transit)

    @property
    def transfers(self) -> int:
        """How many hand-overs took place (arrived, with a latency)."""
        return self._transfers

    @property
    def events(self) -> Sequence[ItemEvent]:
        """Every event, in the order it happened (a read-only live view)."""
        return EventsView(self._events)

    def holder(self, item: ItemId) -> RobotId | None:
        """The robot holding ``item`` now; ``None`` once it is retired, or on its way.

        Raises:
            SimulationError: no such item was created.
        """
        self._history(item)
        return self._holder.get(item)

    def held_by(self, robot: RobotId) -> tuple[ItemId, ...]:
        """The items ``robot`` holds now, in the order it received them."""
        return tuple(self._held.get(robot, ()))

    def travelling_with(self, robot: RobotId) -> tuple[ItemId, ...]:
        """The items on their way from or to ``robot`` now (sent, or refused and going back)."""
        return tuple(item for item, way in self._transit.items() if robot in way)

    def holders(self) -> tuple[RobotId, ...]:
        """Every robot that holds at least one item now (in no particular order)."""
        return tuple(self._held)  # a robot that holds nothing is not listed

    def history(self, item: ItemId) -> tuple[ItemEvent, ...]:
        """Every event of ``item``, oldest first (its first is ``CREATED``, here).

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
            SimulationError: ``t`` is not finite, or ``holder`` made ``ID_SPAN`` items.
        """
        _check_time(t, f"creating an item for robot {holder}")
        if self._by_creator:
            made = self._made.get(holder, 0) + 1
            if made >= ID_SPAN:
                raise SimulationError(f"robot {holder} created {ID_SPAN - 1} items: no id left")
            self._made[holder] = made
            item = holder * ID_SPAN + made
        else:
            item = self._created + 1
        self._created += 1
        self._add(item, holder, ItemEvent(t, ItemEventKind.CREATED, item, holder))
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

    def send(self, item: ItemId, giver: RobotId, receiver: RobotId, t: float) -> None:
        """``item`` leaves ``giver``'s hands at ``t``, on its way to ``receiver``.

        Raises:
            SimulationError: as :meth:`transfer`. Nothing changes then.
        """
        action = f"robot {giver} sending item {item} to robot {receiver}"
        self._check_event(item, giver, t, action)
        if receiver == giver:
            raise SimulationError(f"{action}: a robot cannot hand an item to itself")
        self._drop(item, giver)
        self._transit[item] = (giver, receiver)
        self._record(ItemEvent(t, ItemEventKind.SENT, item, giver, receiver), giver)

    def arrive(self, item: ItemId, giver: RobotId, receiver: RobotId, t: float) -> None:
        """``item``, sent by ``giver``, arrives in ``receiver``'s hands at ``t``.

        Raises:
            SimulationError: the item is not on its way from ``giver`` to ``receiver``
                (in a partial ledger, an item never seen may arrive).
        """
        self._on_way(item, giver, receiver, t, "arriving")
        self._transit.pop(item, None)
        self._holder[item] = receiver
        self._held.setdefault(receiver, {})[item] = None
        self._transfers += 1
        self._record(ItemEvent(t, ItemEventKind.TRANSFERRED, item, giver, receiver), receiver)

    def refuse(self, item: ItemId, giver: RobotId, receiver: RobotId, t: float) -> None:
        """``item`` arrives at ``receiver`` at ``t`` but is refused: it travels back to ``giver``.

        Raises:
            SimulationError: as :meth:`arrive`.
        """
        self._on_way(item, giver, receiver, t, "refusing")
        self._transit[item] = (receiver, giver)
        self._record(ItemEvent(t, ItemEventKind.REFUSED, item, giver, receiver), receiver)

    def returned(self, item: ItemId, giver: RobotId, t: float) -> None:
        """A refused ``item`` is back in ``giver``'s hands at ``t``.

        In a partial ledger the refusal may have happened in another ledger (the
        receiver's): here the item is then still on its way from ``giver``.

        Raises:
            SimulationError: the item is not on its way back to ``giver``.
        """
        way = self._transit.get(item)
        if way is None or (way[1] != giver and not (self._partial and way[0] == giver)):
            raise SimulationError(f"item {item} is not on its way back to robot {giver}")
        del self._transit[item]
        self._holder[item] = giver
        self._held.setdefault(giver, {})[item] = None
        self._record(ItemEvent(t, ItemEventKind.RETURNED, item, giver), giver)

    def handed_away(self, item: ItemId) -> None:
        """A partial ledger's item leaves it for another ledger's robot.

        It arrived there, or it was refused here and travels back to its giver there.
        """
        way = self._transit.pop(item, None)
        if way is None:
            raise SimulationError(f"item {item} is not on its way from this ledger")
        self._histories.pop(item, None)

    def retire(self, item: ItemId, holder: RobotId, t: float) -> None:
        """Retires ``item``, held by ``holder``, at instant ``t``: nobody holds it any more.

        Raises:
            SimulationError: the item is unknown or retired already, ``holder`` does
                not hold it, or ``t`` is not finite or precedes the item's previous
                event. Nothing changes then.
        """
        self._check_event(item, holder, t, f"robot {holder} retiring item {item}")
        self._drop(item, holder)
        self._retired += 1
        self._record(ItemEvent(t, ItemEventKind.RETIRED, item, holder), holder)

    def apply(self, event: ItemEvent) -> None:
        """Records an event that happened in another ledger (one that sees every item).

        Events must come in the order they happened (see :class:`ItemEvent`).

        Raises:
            SimulationError: the event does not follow from the item's story so far.
        """
        kind, item, robot, receiver, t = (
            event.kind,
            event.item,
            event.robot,
            event.receiver,
            event.t,
        )
        if kind is ItemEventKind.CREATED:
            if item in self._histories:
                raise SimulationError(f"item {item} is created twice")
            self._created += 1
            self._add(item, robot, event)
        elif kind is ItemEventKind.RETIRED:
            self.retire(item, robot, t)
        elif kind is ItemEventKind.RETURNED:
            self.returned(item, robot, t)
        elif receiver is None:
            raise SimulationError(f"a {kind.value} event of item {item} names no receiver")
        elif kind is ItemEventKind.SENT:
            self.send(item, robot, receiver, t)
        elif kind is ItemEventKind.REFUSED:
            self.refuse(item, robot, receiver, t)
        elif item in self._transit:
            self.arrive(item, robot, receiver, t)
        else:
            self.transfer(item, robot, receiver, t)

    # -- the invariant ------------------------------------------------------------------

    def check(self) -> None:
        """Verifies that no item was lost or duplicated, in O(items).

        Every created item is retired (and nobody holds it), held by exactly one
        robot, or on its way to exactly one, and the item -> holder and robot ->
        items indexes agree.

        Raises:
            SimulationError: describing the first violation found.
        """
        live = 0
        for item, history in self._histories.items():
            if history[-1].kind is ItemEventKind.RETIRED:
                if item in self._holder or item in self._transit:
                    raise SimulationError(
                        f"item {item} was retired but {self._describe_holder(item)} still holds it"
                    )
            elif item in self._transit:
                if item in self._holder:
                    raise SimulationError(
                        f"item {item} is on its way and held by robot {self._holder[item]}"
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
        travelling = len(self._transit)
        if not self._partial and live + travelling + self._retired != self._created:
            way = f", {travelling} on their way" if travelling else ""
            raise SimulationError(
                f"{self._created} items were created, but {live} are held{way} and "
                f"{self._retired} counted as retired"
            )

    # -- internals ----------------------------------------------------------------------

    def _add(self, item: ItemId, holder: RobotId, event: ItemEvent) -> None:
        self._histories[item] = []
        self._holder[item] = holder
        self._held.setdefault(holder, {})[item] = None
        self._record(event, holder)

    def _history(self, item: ItemId) -> list[ItemEvent]:
        history = self._histories.get(item) if isinstance(item, int) else None
        if history is None:
            raise SimulationError(f"item {item!r} is unknown: {self.created} items were created")
        return history

    def _on_way(self, item: ItemId, giver: RobotId, receiver: RobotId, t: float, what: str) -> None:
        """Checks that ``item`` is on its way from ``giver`` to ``receiver`` (see ``arrive``)."""
        _check_time(t, f"item {item} {what} at robot {receiver}")
        if self._transit.get(item) == (giver, receiver):
            if t < self._histories[item][-1].t:
                raise SimulationError(f"item {item} {what} at {t!r}: time does not go backwards")
            return
        if self._partial and item not in self._histories:  # from another ledger's robot
            self._histories[item] = []
            self._transit[item] = (giver, receiver)
            return
        raise SimulationError(
            f"item {item} {what} at robot {receiver}: it is not on its way from robot {giver}"
        )

    def _check_event(self, item: ItemId, robot: RobotId, t: float, action: str) -> None:
        """The preconditions shared by transfer, send and retire."""
        history = self._history(item)
        last = history[-1]
        if last.kind is ItemEventKind.RETIRED:
            raise SimulationError(f"{action}: item {item} was retired at {last.t!r}")
        holder = self._holder.get(item)
        if holder != robot:
            raise SimulationError(
                f"{action}: robot {robot} does not hold it ({self._describe_holder(item)} does)"
            )
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
        del self._holder[item]
        if not items:
            del self._held[robot]  # robots that hold nothing are not listed

    def _record(self, event: ItemEvent, *touched: RobotId) -> None:
        self._histories[event.item].append(event)
        self._events.append(event)
        if self._checking:
            self._check_local(event.item, touched)
        for callback in self._subscribers:
            callback(event)

    def _check_local(self, item: ItemId, robots: tuple[RobotId, ...]) -> None:
        """The invariant restricted to one item and the robots an event touched."""
        retired = self._histories[item][-1].kind is ItemEventKind.RETIRED
        travelling = item in self._transit
        if (retired or travelling) and item in self._holder:
            raise SimulationError(
                f"item {item} is {'retired' if retired else 'on its way'} but held"
            )
        if not retired and not travelling:
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
        if holder is not None:
            return f"robot {holder}"
        way = self._transit.get(item)
        if way is not None:
            return f"the way from robot {way[0]} to robot {way[1]}"
        return "nobody"


def _check_time(t: float, action: str) -> None:
    if not math.isfinite(t):
        raise SimulationError(f"{action}: t must be a finite number, got {t!r}")
