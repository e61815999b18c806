"""Deliveries: effects of one robot on another, run at their instants in (instant, key) order."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import gc
import math
import weakref
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from cas_async import VirtualTimeLoop
from cas_async._time._deliveries import DATAGRAM, ITEM, MOTION, RECEIPT, Deliveries

Log = list[tuple[float, object]]


def logger(log: Log, loop: asyncio.AbstractEventLoop, label: object) -> Callable[[], None]:
    """An action that notes the loop time it ran at, and ``label``."""
    return lambda: log.append((loop.time(), label))


@contextlib.contextmanager
def reported() -> Iterator[list[dict[str, Any]]]:
    """What the running loop's exception handler is given meanwhile."""
    contexts: list[dict[str, Any]] = []
    loop = asyncio.get_running_loop()
    loop.set_exception_handler(lambda _loop, context: contexts.append(context))
    try:
        yield contexts
    finally:
        loop.set_exception_handler(None)


def test_the_kinds_order_motions_items_receipts_then_datagrams() -> None:
    assert MOTION < ITEM < RECEIPT < DATAGRAM


def test_each_loop_has_one_deliveries_made_on_first_use() -> None:
    first, second = asyncio.new_event_loop(), VirtualTimeLoop()
    try:
        deliveries = Deliveries.of(first)
        assert Deliveries.of(first) is deliveries
        assert Deliveries.of(second) is not deliveries
        assert Deliveries.of(second) is Deliveries.of(second)
    finally:
        first.close()
        second.close()


def test_a_closed_loop_and_what_its_deliveries_hold_are_let_go() -> None:
    # The deliveries of a run hold its robots (their actions reach them) and so its
    # loop: a loop that has closed must not stay in memory for every later run.
    class Payload:
        pass

    loop, payload = VirtualTimeLoop(), Payload()
    Deliveries.of(loop).at(5.0, (DATAGRAM, 1, 1), functools.partial(print, payload, loop))
    gone_loop, gone_payload = weakref.ref(loop), weakref.ref(payload)
    loop.close()
    del loop, payload
    other = VirtualTimeLoop()
    try:
        Deliveries.of(other)  # the next run's first use
        gc.collect()
        assert gone_loop() is None
        assert gone_payload() is None
    finally:
        other.close()


@pytest.mark.cas_virtual
async def test_of_without_a_loop_is_the_running_loops() -> None:
    assert Deliveries.of() is Deliveries.of(asyncio.get_running_loop())


# -- virtual time ------------------------------------------------------------------------


@pytest.mark.cas_virtual
async def test_actions_run_at_their_instants_by_instant_then_key_whatever_the_order_given() -> None:
    loop = asyncio.get_running_loop()
    deliveries, log = Deliveries.of(), []
    given = [
        (2.0, (DATAGRAM, 1, 1)),
        (1.0, (DATAGRAM, 2, 1)),
        (1.0, (MOTION, 9, 1)),
        (2.0, (ITEM, 3, 1)),
        (1.0, (DATAGRAM, 1, 2)),
        (1.0, (DATAGRAM, 1, 1)),
        (0.5, (RECEIPT, 7, 4)),
    ]
    for when, key in given:
        deliveries.at(when, key, logger(log, loop, key))
    assert len(deliveries) == len(given)
    assert deliveries.next_at() == 0.5
    await asyncio.sleep(10.0)
    assert log == sorted(given)
    assert len(deliveries) == 0
    assert deliveries.next_at() == math.inf


@pytest.mark.cas_virtual
async def test_ties_of_equal_keys_keep_the_order_they_were_given_in() -> None:
    loop = asyncio.get_running_loop()
    deliveries, log = Deliveries.of(), []
    for label in "abcde":
        deliveries.at(1.0, (DATAGRAM, 1, 1), logger(log, loop, label))
    await asyncio.sleep(2.0)
    assert [label for _, label in log] == list("abcde")


@pytest.mark.cas_virtual
async def test_deliveries_of_an_instant_run_before_its_timers_even_those_armed_first() -> None:
    loop = asyncio.get_running_loop()
    deliveries, log = Deliveries.of(), []
    loop.call_at(3.0, logger(log, loop, "timer at 3"))
    sleeper = asyncio.ensure_future(asyncio.sleep(3.0))
    sleeper.add_done_callback(lambda _: log.append((loop.time(), "sleep until 3")))
    loop.call_at(2.0, logger(log, loop, "timer at 2"))
    deliveries.at(3.0, (DATAGRAM, 1, 1), logger(log, loop, "delivery at 3"))
    deliveries.at(2.5, (DATAGRAM, 1, 2), logger(log, loop, "delivery at 2.5"))
    await sleeper
    await asyncio.sleep(1.0)
    assert log == [
        (2.0, "timer at 2"),
        (2.5, "delivery at 2.5"),
        (3.0, "delivery at 3"),
        (3.0, "timer at 3"),
        (3.0, "sleep until 3"),
    ]


@pytest.mark.cas_virtual
async def test_what_a_delivery_wakes_runs_before_a_timer_it_arms_for_its_own_instant() -> None:
    """At an instant with no timer, the loop runs its deliveries without a pass of their own."""
    loop = asyncio.get_running_loop()
    log: Log = []
    woken = loop.create_future()

    async def sleeper() -> None:
        await woken
        log.append((loop.time(), "task woken"))

    def action() -> None:
        log.append((loop.time(), "delivery"))
        loop.call_at(loop.time(), logger(log, loop, "timer armed for now"))
        woken.set_result(None)
        loop.call_soon(logger(log, loop, "soon"))

    task = asyncio.ensure_future(sleeper())
    loop.call_at(2.0, logger(log, loop, "timer at 2"))
    Deliveries.of().at(1.5, (DATAGRAM, 1, 1), action)
    await task
    await asyncio.sleep(1.0)
    assert log == [
        (1.5, "delivery"),
        (1.5, "task woken"),
        (1.5, "soon"),
        (1.5, "timer armed for now"),
        (2.0, "timer at 2"),
    ]


@pytest.mark.cas_virtual
async def test_the_loop_jumps_to_a_delivery_when_no_timer_is_armed() -> None:
    loop = asyncio.get_running_loop()
    assert isinstance(loop, VirtualTimeLoop)
    arrived = loop.create_future()
    Deliveries.of().at(42.25, (DATAGRAM, 1, 1), lambda: arrived.set_result(loop.time()))
    assert loop.next_deadline() == 42.25
    assert await arrived == 42.25
    assert loop.time() == 42.25


@pytest.mark.cas_virtual
async def test_the_loops_next_deadline_is_its_next_timer_or_delivery() -> None:
    loop = asyncio.get_running_loop()
    assert isinstance(loop, VirtualTimeLoop)
    deliveries = Deliveries.of()
    timer = loop.call_at(7.0, lambda: None)
    assert loop.next_deadline() == 7.0
    deliveries.at(4.0, (ITEM, 1, 1), lambda: None)
    assert loop.next_deadline() == 4.0
    await asyncio.sleep(5.0)
    assert loop.next_deadline() == 7.0
    timer.cancel()


@pytest.mark.cas_virtual
async def test_an_action_may_schedule_a_later_delivery_but_not_one_at_its_own_instant() -> None:
    loop = asyncio.get_running_loop()
    deliveries, log = Deliveries.of(), []
    refused: list[ValueError] = []

    def first() -> None:
        log.append((loop.time(), "first"))
        deliveries.at(1.5, (DATAGRAM, 1, 2), logger(log, loop, "second"))
        try:
            deliveries.at(1.0, (DATAGRAM, 1, 3), logger(log, loop, "at once"))
        except ValueError as error:
            refused.append(error)

    deliveries.at(1.0, (DATAGRAM, 1, 1), first)
    await asyncio.sleep(2.0)
    assert log == [(1.0, "first"), (1.5, "second")]
    assert len(refused) == 1


@pytest.mark.cas_virtual
@pytest.mark.parametrize("ahead", [0.0, -1.0, math.nan], ids=["now", "past", "nan"])
async def test_on_virtual_time_a_delivery_due_at_or_before_now_is_refused(ahead: float) -> None:
    await asyncio.sleep(10.0)
    deliveries = Deliveries.of()
    with pytest.raises(ValueError, match=r"due after now \(10\.0\)"):
        deliveries.at(10.0 + ahead, (DATAGRAM, 1, 1), lambda: None)
    assert len(deliveries) == 0
    assert deliveries.late == 0


@pytest.mark.cas_virtual
@pytest.mark.parametrize("error", [RuntimeError, asyncio.CancelledError])
async def test_an_action_that_raises_is_reported_and_the_others_still_run(
    error: type[BaseException],
) -> None:
    loop = asyncio.get_running_loop()
    deliveries, log = Deliveries.of(), []

    def broken() -> None:
        raise error("the receiver broke")

    deliveries.at(1.0, (DATAGRAM, 1, 1), logger(log, loop, "before"))
    deliveries.at(1.0, (DATAGRAM, 2, 1), broken)
    deliveries.at(1.0, (DATAGRAM, 3, 1), logger(log, loop, "after"))
    deliveries.at(2.0, (DATAGRAM, 1, 2), logger(log, loop, "later"))
    with reported() as contexts:
        await asyncio.sleep(3.0)
    assert log == [(1.0, "before"), (1.0, "after"), (2.0, "later")]
    assert len(contexts) == 1
    assert contexts[0]["message"] == "a delivery failed"
    assert str(contexts[0]["exception"]) == "the receiver broke"


def test_run_due_runs_what_is_due_in_order_and_says_how_many() -> None:
    loop = VirtualTimeLoop()
    try:
        deliveries, log = Deliveries(loop), []
        for when, key in [(3.0, (DATAGRAM, 1, 1)), (1.0, (DATAGRAM, 2, 1)), (2.0, (MOTION, 1, 1))]:
            deliveries.at(when, key, logger(log, loop, when))
        assert deliveries.run_due(0.5) == 0
        assert deliveries.run_due(2.0) == 2
        assert [label for _, label in log] == [1.0, 2.0]
        assert deliveries.next_at() == 3.0
        assert deliveries.run_due(math.inf) == 1
        assert len(deliveries) == 0
    finally:
        loop.close()


# -- scaled (real) time: a plain loop --------------------------------------------------


async def test_on_a_plain_loop_a_timer_runs_them_in_order() -> None:
    loop = asyncio.get_running_loop()
    assert not isinstance(loop, VirtualTimeLoop)
    deliveries, log = Deliveries.of(), []
    base = loop.time()
    for when, key in [(0.03, (DATAGRAM, 2, 1)), (0.01, (DATAGRAM, 1, 1)), (0.03, (MOTION, 5, 1))]:
        deliveries.at(base + when, key, logger(log, loop, key))
    finished = loop.create_future()
    deliveries.at(base + 0.04, (DATAGRAM, 9, 9), lambda: finished.set_result(None))
    await asyncio.wait_for(finished, 30.0)
    assert [label for _, label in log] == [(DATAGRAM, 1, 1), (MOTION, 5, 1), (DATAGRAM, 2, 1)]
    # None ran before its instant (a timer may go off a hair early: the loop's resolution).
    for (ran, key), due in zip(log, [0.01, 0.03, 0.03], strict=True):
        assert ran >= base + due - 0.01, key
    assert (deliveries.late, deliveries.most_late) == (0, 0.0)


async def test_on_a_plain_loop_an_earlier_delivery_given_later_runs_first() -> None:
    loop = asyncio.get_running_loop()
    deliveries = Deliveries.of()
    deliveries.at(loop.time() + 3600.0, (DATAGRAM, 1, 1), lambda: None)
    soon = loop.create_future()
    deliveries.at(loop.time() + 0.01, (DATAGRAM, 1, 2), lambda: soon.set_result(None))
    await asyncio.wait_for(soon, 30.0)  # not an hour
    assert len(deliveries) == 1
    assert deliveries.next_at() > loop.time() + 3000


async def test_on_a_plain_loop_a_late_delivery_runs_as_soon_as_it_can_and_is_counted() -> None:
    loop = asyncio.get_running_loop()
    deliveries, log = Deliveries.of(), []
    now = loop.time()
    deliveries.at(now - 1.0, (DATAGRAM, 1, 2), logger(log, loop, "a second late"))
    deliveries.at(now - 2.5, (DATAGRAM, 1, 1), logger(log, loop, "2.5 s late"))
    deliveries.at(now + 0.01, (DATAGRAM, 1, 3), logger(log, loop, "on time"))
    assert deliveries.late == 2
    assert 2.5 <= deliveries.most_late < 60.0
    assert log == []  # never a re-entrant call: on the loop's next passes
    done = loop.create_future()
    deliveries.at(now + 0.02, (DATAGRAM, 1, 4), lambda: done.set_result(None))
    await asyncio.wait_for(done, 30.0)
    assert [label for _, label in log] == ["2.5 s late", "a second late", "on time"]
    assert deliveries.late == 2


async def test_on_a_plain_loop_an_action_that_raises_does_not_stop_the_others() -> None:
    loop = asyncio.get_running_loop()
    deliveries, log = Deliveries.of(), []

    def broken() -> None:
        raise KeyError("gone")

    base = loop.time()
    deliveries.at(base + 0.01, (DATAGRAM, 1, 1), broken)
    deliveries.at(base + 0.01, (DATAGRAM, 1, 2), logger(log, loop, "same instant"))
    done = loop.create_future()
    deliveries.at(base + 0.02, (DATAGRAM, 1, 3), lambda: done.set_result(None))
    with reported() as contexts:
        await asyncio.wait_for(done, 30.0)
    assert [label for _, label in log] == ["same instant"]
    assert [type(context["exception"]) for context in contexts] == [KeyError]
