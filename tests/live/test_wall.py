"""Waiting on the wall clock from a loop whose clock may be virtual: the Pacer, wall_bounded."""

from __future__ import annotations

import asyncio

import pytest

from cas_async.live._pacer import LAG_LIMIT, SLICE, Pacer, wall_bounded


class FakeWall:
    """A wall clock that moves only when the pacer blocks."""

    def __init__(self) -> None:
        self.now = 100.0
        self.blocks: list[float] = []

    def __call__(self) -> float:
        return self.now

    def block(self, seconds: float) -> None:
        self.blocks.append(seconds)
        self.now += seconds


async def test_the_pacer_holds_until_the_wall_clock_catches_up_in_slices() -> None:
    wall = FakeWall()
    pacer = Pacer(10.0, wall_clock=wall, block=wall.block)
    await pacer.hold(0.0)  # the origin: nothing to wait for
    assert wall.blocks == []
    await pacer.hold(1.0)  # 1 simulated second at 10 per wall second: 0.1 wall seconds
    assert sum(wall.blocks) == pytest.approx(0.1)
    assert max(wall.blocks) <= SLICE + 1e-12
    assert pacer.held == pytest.approx(0.1)


async def test_a_run_behind_the_pace_goes_on_at_once_and_paces_from_there() -> None:
    wall = FakeWall()
    pacer = Pacer(1.0, wall_clock=wall, block=wall.block)
    await pacer.hold(0.0)
    wall.now += 5.0 + LAG_LIMIT + 0.5  # a slow stretch: 5 simulated s took 6.5 wall s
    await pacer.hold(5.0)
    assert wall.blocks == []
    await pacer.hold(5.5)  # paced from where it is: half a wall second
    assert sum(wall.blocks) == pytest.approx(0.5)


async def test_the_pacer_lets_go_when_the_run_stops() -> None:
    wall = FakeWall()
    stop = asyncio.Event()
    stop.set()
    pacer = Pacer(1.0, wall_clock=wall, block=wall.block, stopping=stop.is_set)
    await pacer.hold(0.0)
    await pacer.hold(100.0)
    assert wall.blocks == []


@pytest.mark.parametrize("pace", [0.0, -1.0, float("inf"), float("nan")])
def test_a_pace_that_is_no_positive_number_is_refused(pace: float) -> None:
    with pytest.raises(ValueError, match="positive"):
        Pacer(pace)


async def test_wall_bounded_returns_the_value_or_none_once_the_time_is_up() -> None:
    async def answer() -> int:
        return 42

    assert await wall_bounded(answer(), 5.0) == 42
    assert await wall_bounded(asyncio.Event().wait(), 0.05) is None
