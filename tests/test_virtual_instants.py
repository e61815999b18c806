"""The virtual-time loop reaches a timer's own instant, whatever events came before it.

A run across processes gives the very results of a run in one only if a robot reads
the same time at the same instant in every process, although each process's loop
saw other events before it (those of the robots it runs).
"""

from __future__ import annotations

import asyncio
import random

import pytest

import cas_async
from cas_async import VirtualClock


def reached(instants: list[float], before: list[float]) -> list[float]:
    """The loop times read by timers at ``instants``, on a loop that also had ``before``."""

    async def main() -> list[float]:
        loop = asyncio.get_running_loop()
        read: dict[float, float] = {}
        for when in before:
            loop.call_at(when, lambda: None)
        for when in instants:
            loop.call_at(when, lambda when=when: read.setdefault(when, loop.time()))
        await asyncio.sleep(max(instants) + 1.0)
        return [read[when] for when in instants]

    result: list[float] = cas_async.run(main(), virtual=True)
    return result


def test_a_timer_reads_its_own_instant_whatever_came_before() -> None:
    instants = [1.7, 2.9, 3.3, 10.1, 1e-3 + 7]
    # 0.6 then 1.7: 0.6 + (1.7 - 0.6) is 1.7000000000000002 in floating point.
    assert reached(instants, [0.6, 0.1, 0.3]) == instants
    assert reached(instants, [1.2]) == instants
    rng = random.Random(28)
    assert reached(instants, [rng.uniform(0, 12) for _ in range(200)]) == instants


def test_a_timer_within_a_nanosecond_of_another_event_waits_for_its_own_instant() -> None:
    # asyncio runs every timer due within its clock's resolution (1 ns) of now: on
    # virtual time that ran a robot's timer at another robot's event a fraction of a
    # nanosecond earlier, when the two shared a loop, and at its own instant when
    # they were in two processes (scale_2500: one robot's hand-over, 6e-10 s apart).
    instants = [12.71517256148098, 1.0 + 5e-10, 3.0 + 1e-12, 200_000.3 + 5e-11]
    before = [12.715172560891675, 1.0, 3.0, 200_000.3]
    assert reached(instants, before) == instants
    assert reached(instants, []) == instants


def test_timers_of_one_instant_run_in_the_order_they_were_armed() -> None:
    # asyncio's heap orders by instant alone: how it breaks ties depends on the other
    # timers in it, so one robot's timers of an instant ran in another order when its
    # process ran other robots too (a lossy run differed across processes).
    def order(others: list[float]) -> list[int]:
        async def main() -> list[int]:
            loop = asyncio.get_running_loop()
            ran: list[int] = []
            for when in others:
                loop.call_at(when, lambda: None)
            for n in range(40):
                loop.call_at(2.5, ran.append, n)
                if n % 7 == 0:  # and a cancelled one among them
                    loop.call_at(2.5, ran.append, -1).cancel()
            await asyncio.sleep(3.0)
            return ran

        result: list[int] = cas_async.run(main(), virtual=True)
        return result

    rng = random.Random(46)
    for others in ([], [2.5] * 9, [rng.choice([1.0, 2.5, 4.0]) for _ in range(300)]):
        assert order(others) == list(range(40))


def test_a_timer_more_than_a_day_away_is_reached_exactly() -> None:
    # asyncio waits at most a day at a time: the loop must not stop short of it.
    assert reached([200_000.3], [0.7]) == [200_000.3]


@pytest.mark.cas_virtual
async def test_a_clocks_sleep_until_wakes_at_its_instant() -> None:
    clock = VirtualClock()
    clock.start()
    loop = asyncio.get_running_loop()
    loop.call_at(0.6, lambda: None)
    await clock.sleep_until(0.6)
    await clock.sleep_until(1.7)
    assert clock.now() == 1.7
