"""The item ledger's hand-overs that take time: sent, then taken, or refused and returned."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from cas_async import SimulationError
from cas_async.sim import ItemEvent, ItemEventKind, ItemLedger
from cas_async.sim._items import ID_SPAN

SENT, TRANSFERRED, REFUSED, RETURNED = (
    ItemEventKind.SENT,
    ItemEventKind.TRANSFERRED,
    ItemEventKind.REFUSED,
    ItemEventKind.RETURNED,
)


def checked(**kwargs: bool) -> ItemLedger:
    ledger = ItemLedger(**kwargs)
    ledger.subscribe(lambda _event: ledger.check())
    return ledger


def test_an_item_on_its_way_is_in_nobodys_hands_and_still_counted() -> None:
    ledger = checked()
    item = ledger.create(1, 0.0)
    ledger.send(item, 1, 2, 1.0)
    assert (ledger.holder(item), ledger.held_by(1), ledger.held_by(2)) == (None, (), ())
    assert (ledger.held, ledger.in_transit, ledger.transfers) == (0, 1, 0)
    ledger.arrive(item, 1, 2, 1.5)
    assert (ledger.holder(item), ledger.held, ledger.in_transit, ledger.transfers) == (2, 1, 0, 1)
    event = ledger.events[-1]
    assert (event.kind, event.robot, event.receiver, event.actor) == (TRANSFERRED, 1, 2, 2)


def test_a_refused_item_travels_back_and_is_its_givers_again() -> None:
    ledger = checked()
    item = ledger.create(1, 0.0)
    ledger.send(item, 1, 2, 1.0)
    ledger.refuse(item, 1, 2, 1.5)
    assert (ledger.holder(item), ledger.in_transit) == (None, 1)
    assert ledger.events[-1].actor == 2  # it happened in the receiver's hands
    ledger.returned(item, 1, 2.0)
    assert (ledger.holder(item), ledger.in_transit, ledger.transfers) == (1, 0, 0)
    assert [e.kind for e in ledger.history(item)] == [
        ItemEventKind.CREATED,
        SENT,
        REFUSED,
        RETURNED,
    ]


def test_what_is_on_its_way_cannot_be_handed_retired_or_sent_again() -> None:
    ledger = checked()
    item = ledger.create(1, 0.0)
    ledger.send(item, 1, 2, 1.0)
    with pytest.raises(SimulationError, match="robot 1 does not hold it"):
        ledger.send(item, 1, 3, 1.0)
    with pytest.raises(SimulationError, match="robot 1 does not hold it"):
        ledger.retire(item, 1, 1.0)
    with pytest.raises(SimulationError, match=r"\(the way from robot 1 to robot 2 does\)"):
        ledger.transfer(item, 1, 3, 1.0)


@pytest.mark.parametrize(
    ("step", "message"),
    [
        (lambda ledger, item: ledger.arrive(item, 1, 3, 2.0), "not on its way from robot 1"),
        (lambda ledger, item: ledger.arrive(item, 4, 2, 2.0), "not on its way from robot 4"),
        (lambda ledger, item: ledger.refuse(item, 1, 3, 2.0), "not on its way from robot 1"),
        (lambda ledger, item: ledger.arrive(item, 1, 2, 0.5), "time does not go backwards"),
        (lambda ledger, item: ledger.returned(item, 1, 2.0), "not on its way back to robot 1"),
        (lambda ledger, item: ledger.arrive(item, 1, 2, float("nan")), "finite number"),
    ],
    ids=[
        "wrong-receiver",
        "wrong-giver",
        "refused-by-another",
        "before-it-left",
        "not-refused",
        "nan",
    ],
)
def test_a_step_that_does_not_follow_is_refused_and_changes_nothing(
    step: Callable[[ItemLedger, int], None], message: str
) -> None:
    ledger = checked()
    item = ledger.create(1, 0.0)
    ledger.send(item, 1, 2, 1.0)
    events = len(ledger.events)
    with pytest.raises(SimulationError, match=message):
        step(ledger, item)
    assert len(ledger.events) == events
    assert ledger.in_transit == 1
    ledger.check()


def test_a_full_ledger_takes_no_item_it_never_saw() -> None:
    ledger = checked()
    with pytest.raises(SimulationError, match="not on its way from robot 1"):
        ledger.arrive(7, 1, 2, 1.0)


def test_a_partial_ledger_takes_items_from_other_ledgers_and_lets_them_go() -> None:
    ledger = checked(partial=True)
    visitor = 9 * ID_SPAN + 1  # made by another ledger's robot 9
    ledger.arrive(visitor, 9, 2, 1.0)  # never seen here: it came from elsewhere
    assert (ledger.holder(visitor), ledger.created, ledger.held) == (2, 0, 1)
    ledger.send(visitor, 2, 9, 2.0)
    ledger.handed_away(visitor)  # it arrived there
    with pytest.raises(SimulationError, match="unknown"):
        ledger.holder(visitor)
    with pytest.raises(SimulationError, match="not on its way from this ledger"):
        ledger.handed_away(visitor)
    ledger.arrive(visitor, 9, 2, 3.0)  # back again, a new visit
    assert ledger.holder(visitor) == 2


def test_a_partial_ledger_gets_back_an_item_refused_in_another_ledger() -> None:
    ledger = checked(partial=True)
    item = ledger.create(1, 0.0)
    assert item == 1 * ID_SPAN + 1  # ids by creator, whatever else the ledger holds
    ledger.send(item, 1, 9, 1.0)  # robot 9's ledger refuses it (its REFUSED event is there)
    ledger.returned(item, 1, 2.0)
    assert (ledger.holder(item), ledger.in_transit) == (1, 0)
    with pytest.raises(SimulationError, match="not on its way back to robot 1"):
        ledger.returned(item, 1, 3.0)


def test_a_ledger_that_sees_everything_applies_a_story_of_steps_in_order() -> None:
    story = [
        ItemEvent(0.0, ItemEventKind.CREATED, 5, 1),
        ItemEvent(1.0, SENT, 5, 1, 2),
        ItemEvent(1.5, REFUSED, 5, 1, 2),
        ItemEvent(2.0, RETURNED, 5, 1),
        ItemEvent(3.0, SENT, 5, 1, 2),
        ItemEvent(3.5, TRANSFERRED, 5, 1, 2),
    ]
    whole = checked()
    for event in story:
        whole.apply(event)
    assert list(whole.events) == story
    assert (whole.holder(5), whole.transfers, whole.in_transit) == (2, 1, 0)
    with pytest.raises(SimulationError, match="a sent event of item 5 names no receiver"):
        whole.apply(ItemEvent(4.0, SENT, 5, 2))


def test_the_items_travelling_with_a_robot_are_those_on_their_way_to_or_from_it() -> None:
    ledger = checked()
    first, second, kept = ledger.create(1, 0.0), ledger.create(1, 0.0), ledger.create(3, 0.0)
    ledger.send(first, 1, 2, 1.0)
    ledger.send(second, 1, 3, 1.0)
    assert ledger.travelling_with(1) == (first, second)
    assert (ledger.travelling_with(2), ledger.travelling_with(3)) == ((first,), (second,))
    ledger.refuse(second, 1, 3, 1.5)  # on its way back: still between them
    assert ledger.travelling_with(3) == (second,)
    ledger.arrive(first, 1, 2, 1.5)
    ledger.returned(second, 1, 2.0)
    assert ledger.travelling_with(1) == ledger.travelling_with(3) == ()
    assert ledger.held_by(3) == (kept,)
