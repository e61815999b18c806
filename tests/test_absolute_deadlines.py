"""Sleeps to absolute deadlines do not drift, and no timer wakes before its instant."""

from __future__ import annotations

import asyncio
import functools
import random

import pytest

import cas_async
from cas_async import Clock, ScaledClock, VirtualClock, loop_factory, uvloop_available
from cas_async._time._deliveries import DATAGRAM, Deliveries

STEPS = 1000
DT = 0.1  # not a binary fraction: rounding would show


def _stamp(future: asyncio.Future[float], clock: Clock) -> None:
    future.set_result(clock.now())


async def _stepping(clock: Clock, *, absolute: bool, seed: int = 1) -> list[float]:
    """``STEPS`` steps of ``DT``, each doing work that takes up to 90% of a step.

    The work is simulated time passing (a fake slow step). Returns ``now()`` at
    every step's end.
    """
    rng = random.Random(seed)
    clock.start()
    start = clock.now()
    ends = []
    for n in range(1, STEPS + 1):
        await clock.sleep(rng.uniform(0.0, 0.9 * DT))  # the step's work
        if absolute:
            await clock.sleep_until(start + n * DT)
        else:
            await clock.sleep(DT)
        ends.append(clock.now())
    return ends


def test_virtual_steps_land_exactly_on_start_plus_n_dt() -> None:
    ends = cas_async.run(_stepping(VirtualClock(), absolute=True), virtual=True)
    assert ends == [n * DT for n in range(1, STEPS + 1)]
    assert ends[-1] == STEPS * DT


def test_relative_sleeps_accumulate_the_work_absolute_ones_do_not() -> None:
    relative = cas_async.run(_stepping(VirtualClock(), absolute=False), virtual=True)
    # Each step lasts its work plus DT: about 45% more in all, as the work averages 0.45 DT.
    assert relative[-1] == pytest.approx(STEPS * DT * 1.45, rel=0.05)


def test_a_later_start_shifts_every_deadline_and_nothing_else() -> None:
    async def main() -> list[float]:
        await asyncio.sleep(12.345)  # the loop's own virtual time has moved before the clock
        return await _stepping(VirtualClock(), absolute=True)

    ends = cas_async.run(main(), virtual=True)
    # Simulated time is loop time minus the origin: off by a rounding of 12.345 at
    # most, the same at the last step as at the first (nothing accumulates).
    errors = [abs(end - n * DT) for n, end in enumerate(ends, start=1)]
    assert max(errors) < 1e-12


def test_scaled_steps_on_a_virtual_loop_never_drift() -> None:
    # ScaledClock on the virtual-time loop: deterministic, and no real waiting.
    clock = ScaledClock(time_factor=100)

    async def main() -> list[float]:
        return await _stepping(clock, absolute=True)

    ends = cas_async.run(main(), virtual=True)
    for n, end in enumerate(ends, start=1):
        assert n * DT <= end <= n * DT + 1e-6, f"step {n} ended at {end!r}"


def test_a_deadline_in_the_past_just_yields() -> None:
    async def main() -> tuple[float, float]:
        clock = VirtualClock()
        clock.start()
        await clock.sleep(5.0)
        await clock.sleep_until(1.0)
        return clock.now(), clock.loop_time_at(2.0) - clock.loop_time_at(0.0)

    assert cas_async.run(main(), virtual=True) == (5.0, 2.0)


def test_a_cancelled_sleep_until_leaves_no_timer() -> None:
    async def main() -> int:
        clock = VirtualClock()
        clock.start()
        sleeper = asyncio.ensure_future(clock.sleep_until(1000.0))
        await asyncio.sleep(1.0)
        sleeper.cancel()
        with pytest.raises(asyncio.CancelledError):
            await sleeper
        loop = asyncio.get_running_loop()
        return sum(not h.cancelled() for h in loop._scheduled)  # type: ignore[attr-defined]

    assert cas_async.run(main(), virtual=True) == 0


LOOPS = [pytest.param(False, id="stdlib")]
if uvloop_available():
    LOOPS.append(pytest.param(True, id="uvloop"))


@pytest.mark.parametrize("use_uvloop", LOOPS)
def test_real_time_timers_never_wake_before_their_instant(use_uvloop: bool) -> None:
    # uvloop rounds delays to whole milliseconds (and runs those under half a
    # millisecond at once): at factor 1000, 0.3 simulated seconds is 0.3 ms. About
    # 40 ms of real time in all; only the order of instants is checked, not durations.
    clock = ScaledClock(time_factor=1000)
    rng = random.Random(3)
    early: list[tuple[str, float, float]] = []

    async def main() -> None:
        loop = asyncio.get_running_loop()
        clock.start()
        for _ in range(20):
            seconds = rng.uniform(0.05, 0.9)
            due = clock.now() + seconds
            await clock.sleep(seconds)
            if clock.now() < due:
                early.append(("sleep", clock.now(), due))
            due = clock.now() + seconds
            await clock.sleep_until(due)
            if clock.now() < due:
                early.append(("sleep_until", clock.now(), due))
            woken = loop.create_future()
            due = clock.now() + seconds
            loop.call_at(clock.loop_deadline(seconds), woken.set_result, None)
            await woken
            if clock.now() < due:
                early.append(("loop_deadline", clock.now(), due))
            due = clock.now() + seconds
            with pytest.raises(TimeoutError):
                async with clock.timeout(seconds):
                    await loop.create_future()
            if clock.now() < due:
                early.append(("timeout", clock.now(), due))
            # What one robot does to another at a later instant (an item, a datagram)
            # runs when the robot's clock has reached that instant, never before.
            delivered: asyncio.Future[float] = loop.create_future()
            due = clock.now() + seconds
            stamp = functools.partial(_stamp, delivered, clock)
            Deliveries.of(loop).at(clock.loop_time_at(due), (DATAGRAM, 1, 1), stamp)
            if (now := await delivered) < due:
                early.append(("delivery", now, due))

    with asyncio.Runner(loop_factory=loop_factory(use_uvloop=use_uvloop)) as runner:
        runner.run(main())
    assert early == []
