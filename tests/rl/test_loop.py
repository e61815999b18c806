"""The stepping loop pauses between steps without changing the run it pauses."""

from __future__ import annotations

import asyncio
import math
import random

import pytest

pytest.importorskip("pettingzoo")

from cas_async import VirtualTimeLoop
from cas_async.rl._stepping_loop import SteppingLoop


async def swarm_of_timers(log: list[tuple[float, int]], seed: int) -> None:
    """Tasks that sleep odd amounts, some to the same instants, and log when they wake."""
    rng = random.Random(seed)

    async def worker(name: int) -> None:
        loop = asyncio.get_running_loop()
        for _ in range(30):
            await asyncio.sleep(rng.choice([0.3, 0.7, 1.1, 0.1 * rng.randint(1, 9)]))
            log.append((loop.time(), name))

    async with asyncio.TaskGroup() as group:
        for name in range(8):
            group.create_task(worker(name))


def test_a_run_stepped_in_pieces_is_the_run_in_one_piece_to_the_last_bit() -> None:
    whole: list[tuple[float, int]] = []
    loop = VirtualTimeLoop()
    try:
        loop.run_until_complete(swarm_of_timers(whole, seed=4))
    finally:
        loop.close()
    stepped: list[tuple[float, int]] = []
    stepping = SteppingLoop()
    try:
        task = stepping.create_task(swarm_of_timers(stepped, seed=4))
        k = 0
        while not task.done():
            k += 1
            stepping.run_until(k * 0.45, task)
            assert stepping.time() <= k * 0.45  # the clock never moves past the step's end
        task.result()
    finally:
        stepping.close()
    assert k > 20
    assert stepped == whole  # same instants (floats compared exactly), same order


def test_the_loop_pauses_at_the_last_event_before_the_horizon_and_runs_those_at_it() -> None:
    loop = SteppingLoop()
    fired: list[float] = []
    try:
        for t in (1.0, 2.5, 7.0):
            loop.call_at(t, lambda: fired.append(loop.time()))
        loop.run_until(2.5)
        assert fired == [1.0, 2.5]  # the timer at the horizon itself runs in this step
        assert loop.time() == 2.5
        loop.run_until(5.0)
        assert fired == [1.0, 2.5]
        assert loop.time() == 2.5  # nothing happened: the clock stayed where it was
        loop.run_until(10.0)
        assert fired == [1.0, 2.5, 7.0]
        loop.run_until(20.0)  # no timer left at all: returns at once
        assert loop.time() == 7.0
    finally:
        loop.close()


def test_it_returns_as_soon_as_the_awaited_task_is_done() -> None:
    loop = SteppingLoop()
    try:
        late = loop.call_at(9.0, lambda: None)
        task = loop.create_task(asyncio.sleep(3.0))
        loop.run_until(math.inf, task)
        assert task.done()
        assert loop.time() == 3.0
        loop.run_until(math.inf, task)  # done already: nothing runs
        assert loop.time() == 3.0
        late.cancel()
    finally:
        loop.close()


def test_a_nan_horizon_is_refused() -> None:
    loop = SteppingLoop()
    try:
        with pytest.raises(ValueError, match="horizon"):
            loop.run_until(math.nan)
    finally:
        loop.close()
