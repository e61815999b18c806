"""The item ledger: preconditions, atomicity, events, and the conservation invariant."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import FrozenInstanceError

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cas_async import CasError, SimulationError
from cas_async.sim import ItemEvent, ItemEventKind, ItemLedger

CREATED, TRANSFERRED, RETIRED = (
    ItemEventKind.CREATED,
    ItemEventKind.TRANSFERRED,
    ItemEventKind.RETIRED,
)


@pytest.fixture
def ledger() -> ItemLedger:
    """Items 1 and 2 held by robot 10 (created at 1.0 and 2.0), item 3 retired by robot 20."""
    book = ItemLedger()
    book.create(10, 1.0)
    book.create(10, 2.0)
    book.create(20, 2.0)
    book.retire(3, 20, 3.0)
    return book


def snapshot(book: ItemLedger) -> object:
    """Everything observable about a ledger, to compare before and after a call."""
    return (
        [book.holder(item) for item in range(1, book.created + 1)],
        {robot: book.held_by(robot) for robot in (10, 20, 30)},
        book.created,
        book.retired,
        book.transfers,
        tuple(book.events),
    )


def test_ids_count_up_from_one_and_robots_hold_in_order_received(ledger: ItemLedger) -> None:
    assert ledger.create(30, 4.0) == 4
    ledger.transfer(4, 30, 10, 5.0)
    assert ledger.held_by(10) == (1, 2, 4)
    ledger.transfer(1, 10, 20, 5.0)
    ledger.transfer(1, 20, 10, 6.0)
    assert ledger.held_by(10) == (2, 4, 1)
    assert ledger.held_by(30) == ()
    assert ledger.held_by(99) == ()


def test_holders_are_the_robots_holding_something_now(ledger: ItemLedger) -> None:
    assert ledger.holders() == (10,)
    ledger.create(30, 4.0)
    assert sorted(ledger.holders()) == [10, 30]
    ledger.retire(4, 30, 5.0)
    assert ledger.holders() == (10,)
    assert ItemLedger().holders() == ()


def test_holder_counts_and_repr(ledger: ItemLedger) -> None:
    assert (ledger.holder(1), ledger.holder(2), ledger.holder(3)) == (10, 10, None)
    assert (ledger.created, ledger.retired, ledger.held, ledger.transfers) == (3, 1, 2, 0)
    ledger.transfer(2, 10, 20, 2.5)
    assert ledger.transfers == 1
    assert repr(ledger) == "ItemLedger(created=3, held=2, retired=1, transfers=1)"


def test_events_and_history_record_every_change(ledger: ItemLedger) -> None:
    ledger.transfer(1, 10, 20, 4.0)
    ledger.retire(1, 20, 4.0)
    assert ledger.history(1) == (
        ItemEvent(1.0, CREATED, 1, 10),
        ItemEvent(4.0, TRANSFERRED, 1, 10, 20),
        ItemEvent(4.0, RETIRED, 1, 20),
    )
    assert ledger.history(3) == (ItemEvent(2.0, CREATED, 3, 20), ItemEvent(3.0, RETIRED, 3, 20))
    assert [(e.kind, e.item) for e in ledger.events] == [
        (CREATED, 1),
        (CREATED, 2),
        (CREATED, 3),
        (RETIRED, 3),
        (TRANSFERRED, 1),
        (RETIRED, 1),
    ]
    assert ledger.events[-1] == ItemEvent(4.0, RETIRED, 1, 20)
    assert ledger.events[1:3] == (ItemEvent(2.0, CREATED, 2, 10), ItemEvent(2.0, CREATED, 3, 20))
    assert len(ledger.events) == 6


def test_events_are_a_read_only_live_view(ledger: ItemLedger) -> None:
    events = ledger.events
    assert not hasattr(events, "append")
    with pytest.raises(TypeError):
        events[0] = events[1]  # type: ignore[index]
    ledger.create(10, 5.0)
    assert len(events) == 5
    with pytest.raises(FrozenInstanceError):
        events[0].t = 9.0  # type: ignore[misc]


def test_subscribers_are_called_after_each_event_in_subscription_order(
    ledger: ItemLedger,
) -> None:
    calls: list[tuple[str, ItemEventKind, int | None]] = []
    ledger.subscribe(lambda event: calls.append(("first", event.kind, ledger.holder(event.item))))
    ledger.subscribe(lambda event: calls.append(("second", event.kind, ledger.holder(event.item))))
    item = ledger.create(30, 4.0)
    ledger.transfer(item, 30, 10, 4.0)
    with pytest.raises(SimulationError):
        ledger.retire(item, 30, 4.0)  # a failed call notifies nobody
    ledger.retire(item, 10, 5.0)
    # Each callback already sees the event's effect.
    assert calls == [
        ("first", CREATED, 30),
        ("second", CREATED, 30),
        ("first", TRANSFERRED, 10),
        ("second", TRANSFERRED, 10),
        ("first", RETIRED, None),
        ("second", RETIRED, None),
    ]


def test_a_failing_subscriber_propagates_but_the_event_stands(ledger: ItemLedger) -> None:
    def refuse(event: ItemEvent) -> None:
        raise RuntimeError(f"saw {event.kind.name}")

    ledger.subscribe(refuse)
    with pytest.raises(RuntimeError, match="saw TRANSFERRED"):
        ledger.transfer(1, 10, 20, 5.0)
    assert ledger.holder(1) == 20
    ledger.check()


BAD_CALLS: list[tuple[Callable[[ItemLedger], object], str]] = [
    (lambda b: b.transfer(9, 10, 20, 5.0), r"item 9 is unknown: 3 items were created"),
    (lambda b: b.transfer(0, 10, 20, 5.0), r"item 0 is unknown"),
    (lambda b: b.retire(4, 10, 5.0), r"item 4 is unknown"),
    (lambda b: b.holder(7), r"item 7 is unknown"),
    (lambda b: b.history(-1), r"item -1 is unknown"),
    (
        lambda b: b.transfer(3, 20, 10, 5.0),
        r"robot 20 handing item 3 to robot 10: item 3 was retired at 3.0",
    ),
    (lambda b: b.retire(3, 20, 5.0), r"robot 20 retiring item 3: item 3 was retired at 3.0"),
    (
        lambda b: b.transfer(1, 20, 30, 5.0),
        r"robot 20 handing item 1 to robot 30: robot 20 does not hold it \(robot 10 does\)",
    ),
    (lambda b: b.retire(2, 30, 5.0), r"robot 30 retiring item 2: robot 30 does not hold it"),
    (
        lambda b: b.transfer(1, 10, 10, 5.0),
        r"robot 10 handing item 1 to robot 10: a robot cannot hand an item to itself",
    ),
    (lambda b: b.transfer(1, 10, 20, math.nan), r"t must be a finite number, got nan"),
    (lambda b: b.transfer(1, 10, 20, math.inf), r"t must be a finite number, got inf"),
    (lambda b: b.retire(1, 10, -math.inf), r"t must be a finite number, got -inf"),
    (lambda b: b.create(10, math.nan), r"creating an item for robot 10: t must be a finite"),
    (
        lambda b: b.transfer(2, 10, 20, 1.5),
        r"handing item 2 to robot 20 at 1.5: the item's previous event was at 2.0",
    ),
    (lambda b: b.retire(2, 10, 1.999), r"retiring item 2 at 1.999: the item's previous event"),
]
BAD_IDS = [
    "transfer-unknown",
    "transfer-zero",
    "retire-unknown",
    "holder-unknown",
    "history-negative",
    "transfer-retired",
    "retire-retired",
    "transfer-not-held",
    "retire-not-held",
    "transfer-to-self",
    "transfer-nan-time",
    "transfer-inf-time",
    "retire-minus-inf-time",
    "create-nan-time",
    "transfer-before-previous",
    "retire-before-previous",
]


@pytest.mark.parametrize(("call", "message"), BAD_CALLS, ids=BAD_IDS)
def test_preconditions_are_refused_and_nothing_changes(
    ledger: ItemLedger, call: Callable[[ItemLedger], object], message: str
) -> None:
    notified: list[ItemEvent] = []
    ledger.subscribe(notified.append)
    before = snapshot(ledger)
    with pytest.raises(SimulationError, match=message) as caught:
        call(ledger)
    assert isinstance(caught.value, CasError)
    assert isinstance(caught.value, ValueError)
    assert snapshot(ledger) == before
    assert notified == []
    ledger.check()
    # The ledger still works normally afterwards.
    ledger.transfer(1, 10, 20, 10.0)
    assert ledger.holder(1) == 20


def test_an_event_at_the_same_instant_as_the_previous_one_is_allowed(ledger: ItemLedger) -> None:
    ledger.transfer(2, 10, 20, 2.0)
    ledger.transfer(2, 20, 30, 2.0)
    ledger.retire(2, 30, 2.0)
    assert ledger.holder(2) is None


def test_times_are_per_item_not_global(ledger: ItemLedger) -> None:
    # Item 1's last event was at 1.0, so it may change hands at 1.5 although item 3
    # was retired at 3.0: robots' clocks only order each item's own events.
    ledger.transfer(1, 10, 20, 1.5)
    assert ledger.history(1)[-1].t == 1.5


# -- check() catches corrupted ledgers ------------------------------------------------------

CORRUPTIONS: list[tuple[Callable[[ItemLedger], object], str]] = [
    (lambda b: b._holder.pop(1), r"item 1 is lost: it was not retired but nobody holds it"),
    (lambda b: b._held[10].pop(2), r"item 2 is held by robot 10, but robot 10 does not list it"),
    (
        lambda b: b._held.setdefault(20, {}).__setitem__(1, None),
        r"robot 20 lists item 1, whose holder is robot 10: the item is duplicated",
    ),
    (lambda b: b._holder.__setitem__(3, 20), r"item 3 was retired but robot 20 still holds it"),
    (
        lambda b: b._held.setdefault(20, {}).__setitem__(3, None),
        r"robot 20 lists item 3, whose holder is nobody",
    ),
    (lambda b: b._holder.__setitem__(99, 20), r"an unknown item is held"),
    (lambda b: setattr(b, "_retired", 0), r"3 items were created, but 2 are held and 0 counted"),
]


@pytest.mark.parametrize(
    ("corrupt", "message"),
    CORRUPTIONS,
    ids=[
        "item-index-lost",
        "robot-index-lost",
        "duplicated",
        "retired-but-held",
        "retired-but-listed",
        "unknown-item-held",
        "retired-count",
    ],
)
def test_check_catches_a_corrupted_ledger(
    ledger: ItemLedger, corrupt: Callable[[ItemLedger], object], message: str
) -> None:
    ledger.check()
    corrupt(ledger)
    with pytest.raises(SimulationError, match=message):
        ledger.check()


def forget_to_drop(book: ItemLedger) -> None:
    """Plants a bug: items are never removed from their previous holder's list."""
    book._drop = lambda item, robot: None  # type: ignore[method-assign]


def test_the_local_check_catches_a_bug_in_the_event_it_ends() -> None:
    book = ItemLedger()
    book.create(10, 0.0)
    forget_to_drop(book)
    with pytest.raises(SimulationError, match="robot 10 lists item 1, whose holder is robot 20"):
        book.transfer(1, 10, 20, 1.0)


def test_the_local_check_can_be_turned_off() -> None:
    book = ItemLedger(checking=False)
    book.create(10, 0.0)
    forget_to_drop(book)
    book.retire(1, 10, 1.0)  # not noticed by the event...
    with pytest.raises(SimulationError, match="item 1 was retired but robot 10 still holds it"):
        book.check()  # ...but by the full check


def test_an_event_on_a_corrupted_item_is_refused_before_changing_anything(
    ledger: ItemLedger,
) -> None:
    del ledger._held[10][1]
    with pytest.raises(SimulationError, match="the ledger is corrupted: robot 10 does not list"):
        ledger.transfer(1, 10, 20, 5.0)
    assert ledger.holder(1) == 10
    assert ledger.transfers == 0


# -- property: random sequences keep the invariant -----------------------------------------

ROBOTS = st.integers(min_value=1, max_value=4)
OPERATIONS = st.lists(
    st.one_of(
        st.tuples(st.just("create"), ROBOTS, ROBOTS, st.integers(0, 30)),
        st.tuples(st.just("transfer"), ROBOTS, ROBOTS, st.integers(0, 30)),
        st.tuples(st.just("retire"), ROBOTS, ROBOTS, st.integers(0, 30)),
    ),
    max_size=60,
)


@settings(max_examples=200, deadline=None)
@given(OPERATIONS, st.booleans())
def test_random_sequences_never_lose_nor_duplicate_an_item(
    operations: list[tuple[str, int, int, int]], checking: bool
) -> None:
    book = ItemLedger(checking=checking)
    book.subscribe(lambda _: book.check())  # the full invariant after every event
    model: dict[int, int | None] = {}  # item -> holder, None once retired
    t = 0.0
    for kind, robot, other, pick in operations:
        t += 0.5
        item = pick % (len(model) + 1) + 1 if model else 1  # sometimes an unknown one
        if kind == "create":
            assert book.create(robot, t) == len(model) + 1
            model[len(model) + 1] = robot
            continue
        valid = model.get(item) == robot and (kind == "retire" or other != robot)
        before = snapshot(book)
        if not valid:
            with pytest.raises(SimulationError):
                if kind == "transfer":
                    book.transfer(item, robot, other, t)
                else:
                    book.retire(item, robot, t)
            assert snapshot(book) == before
            continue
        if kind == "transfer":
            book.transfer(item, robot, other, t)
            model[item] = other
        else:
            book.retire(item, robot, t)
            model[item] = None
    book.check()
    held = sum(len(book.held_by(robot)) for robot in range(1, 5))
    assert book.created == book.retired + held == book.retired + book.held
    assert book.created == len(model)
    assert book.retired == sum(holder is None for holder in model.values())
    for item, holder in model.items():
        assert book.holder(item) == holder
    assert len(book.events) == book.created + book.transfers + book.retired


def test_check_is_linear_in_the_number_of_items() -> None:
    # Not a timing assertion: a smoke test that thousands of items and a check
    # after every event stay practical (quadratic work would take minutes here).
    book = ItemLedger()
    for n in range(5000):
        item = book.create(n % 50, float(n))
        book.transfer(item, n % 50, (n + 1) % 50, float(n))
        if n % 2:
            book.retire(item, (n + 1) % 50, float(n))
    book.check()
    assert (book.created, book.retired, book.held, book.transfers) == (5000, 2500, 2500, 5000)
