"""Interrupted moves: cancellation, timeouts and early timers stop the robot where it is."""

from __future__ import annotations

import asyncio
import math

import pytest

import cas_async
from cas_async import Clock, ConstantSpeed, Decelerating, Pose, VirtualClock
from cas_async.sim import Environment, SimulatedMiddleware
from tests.sim.conftest import Sim

PI = math.pi


@pytest.mark.cas_virtual
async def test_cancelling_a_move_leaves_the_robot_where_it_was_then(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> list[object]:
        mw = SimulatedMiddleware(
            env, 1, clock, turn_rate=PI / 2, speed_profile=Decelerating(5, 1, 1)
        )
        move = asyncio.create_task(mw.move_to(0, 14))  # rotate 1 s, then 6 s
        await clock.sleep_until(3.0)
        move.cancel()
        with pytest.raises(asyncio.CancelledError):
            await move
        log: list[object] = [clock.now(), mw.pose(), mw.speed_profile]
        await clock.sleep_until(20.0)
        log.append(mw.pose())
        await mw.move_to(0, 0)  # the middleware is free again
        log.append(mw.pose())
        return log

    now, stopped, profile, later, back = await main(*sim)
    assert now == 3.0
    assert stopped == later == Pose(0, 8, PI / 2)  # 2 s of translation: 5*2 - 2
    assert profile == Decelerating(3, 1, 1)  # aged by the 2 s it translated
    assert back == Pose(0, 0, -PI / 2)


@pytest.mark.cas_virtual
async def test_cancelling_during_the_rotation_stops_the_turn(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> Pose:
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=1.0, speed_profile=ConstantSpeed(1))
        move = asyncio.create_task(mw.rotate_to(2.0))
        await clock.sleep_until(0.5)
        move.cancel()
        await asyncio.gather(move, return_exceptions=True)
        return mw.pose()

    assert await main(*sim) == Pose(0, 0, 0.5)


@pytest.mark.cas_virtual
async def test_timeouts_interrupt_a_move_the_same_way(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> Pose:
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=math.inf, speed_profile=ConstantSpeed(1))
        with pytest.raises(TimeoutError):
            async with clock.timeout(4.0):
                await mw.move_to(10, 0)
        return mw.pose()

    assert await main(*sim) == Pose(4, 0, 0)


class EarlyClock(Clock):
    """Virtual time whose ``sleep_until`` wakes a little before the deadline."""

    is_virtual = True

    @property
    def time_factor(self) -> float:
        return math.inf

    def _loop_time_per_sim_second(self) -> float:
        return 1.0

    async def sleep_until(self, deadline: float) -> None:
        await self.sleep(deadline - 1e-6 - self.now())


def test_a_clock_that_wakes_early_neither_breaks_nor_shortens_moves() -> None:
    async def main() -> list[Pose]:
        env, clock = Environment(), EarlyClock()
        env.add_robot(1, Pose(0, 0))
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=1, speed_profile=ConstantSpeed(1))
        poses = [await mw.move_to(2, 0), await mw.move_to(2, 3)]
        _, since = env.motion_of(1)
        assert since == pytest.approx(2 + PI / 2 + 3)  # the second move started at 2
        return [*poses, mw.pose()]

    first, second, now = cas_async.run(main(), virtual=True)
    assert first == Pose(2, 0)
    assert second == now == Pose(2, 3, PI / 2)


@pytest.mark.cas_virtual
async def test_cancellation_survives_the_robot_leaving_the_environment(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> None:
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=1, speed_profile=ConstantSpeed(1))
        move = asyncio.create_task(mw.move_to(5, 0))
        await clock.sleep(1.0)
        env.remove_robot(1)
        move.cancel()
        with pytest.raises(asyncio.CancelledError):
            await move

    await main(*sim)
