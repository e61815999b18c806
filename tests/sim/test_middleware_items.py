"""Items through the simulated hands, on virtual time: hand-overs between robots."""

from __future__ import annotations

import asyncio
import math

import pytest

from cas_async import (
    ConstantSpeed,
    Hands,
    Middleware,
    Pose,
    SimulationError,
    UnknownRobotError,
    VirtualClock,
)
from cas_async.sim import Environment, ItemEventKind, SimulatedHands, SimulatedMiddleware
from tests.sim.conftest import Sim


def middleware(env: Environment, robot_id: int, clock: VirtualClock) -> SimulatedMiddleware:
    """A robot that turns instantly and drives at 1 m/s."""
    return SimulatedMiddleware(
        env, robot_id, clock, turn_rate=math.inf, speed_profile=ConstantSpeed(1)
    )


def hands(env: Environment, robot_id: int, clock: VirtualClock, **kwargs: float) -> SimulatedHands:
    return SimulatedHands(env, robot_id, clock, **kwargs)


def test_hands_declare_every_item_operation_and_the_middleware_none() -> None:
    operations = {"items", "create_item", "hand_over", "retire_item", "accept_from", "refuse_from"}
    assert operations <= Hands.__abstractmethods__
    assert operations.isdisjoint(Middleware.__abstractmethods__)


@pytest.mark.cas_virtual
async def test_a_robot_carries_an_item_to_another_and_hands_it_over(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> list[object]:
        env.items.subscribe(lambda _: env.items.check())
        env.add_robot(2, Pose(5, 0))
        carrier, keeper = hands(env, 1, clock), hands(env, 2, clock)
        item = await carrier.create_item()
        log: list[object] = [await carrier.items(), await keeper.items()]
        with pytest.raises(SimulationError, match=r"they are 5\.0 apart"):
            await carrier.hand_over(item, 2)
        await middleware(env, 1, clock).move_to(5, 0)
        await carrier.hand_over(item, 2)
        log += [clock.now(), await carrier.items(), await keeper.items()]
        await middleware(env, 2, clock).move_to(5, 2)
        await keeper.retire_item(item)
        log += [await keeper.items(), [(e.t, e.kind, e.robot) for e in env.items.history(item)]]
        return log

    assert await main(*sim) == [
        (1,),
        (),
        5.0,
        (),
        (1,),
        (),
        [
            (0.0, ItemEventKind.CREATED, 1),
            (5.0, ItemEventKind.TRANSFERRED, 1),
            (7.0, ItemEventKind.RETIRED, 2),
        ],
    ]


@pytest.mark.cas_virtual
async def test_a_hand_over_happens_mid_move_where_the_robots_are_then(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> tuple[float, float, tuple[int, ...]]:
        env.add_robot(2, Pose(10, 0))
        walker = middleware(env, 1, clock)
        keeper = hands(env, 2, clock, reach=0.5)
        item = await keeper.create_item()
        move = asyncio.create_task(walker.move_to(20, 0))  # passes robot 2 at t = 10
        await clock.sleep_until(9.0)
        with pytest.raises(SimulationError, match=r"beyond the reach of 0\.5"):
            await keeper.hand_over(item, 1)  # 1 m apart
        await clock.sleep_until(9.5)
        await keeper.hand_over(item, 1)  # exactly 0.5 m apart: within reach
        moved_on = walker.pose().x
        await move
        return clock.now(), moved_on, await hands(env, 1, clock).items()

    assert await main(*sim) == (20.0, 9.5, (1,))


@pytest.mark.cas_virtual
async def test_items_are_listed_in_the_order_received(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> tuple[int, ...]:
        env.add_robot(2, Pose(0, 0))
        me, other = hands(env, 1, clock), hands(env, 2, clock)
        first, second = await other.create_item(), await me.create_item()
        await clock.sleep(1.0)
        await other.hand_over(first, 1)
        third = await me.create_item()
        assert (first, second, third) == (1, 2, 3)
        return await me.items()

    assert await main(*sim) == (2, 1, 3)


@pytest.mark.cas_virtual
async def test_refused_item_calls_leave_everything_in_place(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> None:
        env.add_robot(2, Pose(0, 0))
        me, other = hands(env, 1, clock), hands(env, 2, clock)
        item = await me.create_item()
        with pytest.raises(UnknownRobotError, match="robot 7 is not in the environment"):
            await me.hand_over(item, 7)
        with pytest.raises(SimulationError, match="robot 2 does not hold it"):
            await other.hand_over(item, 1)
        with pytest.raises(SimulationError, match="robot 2 does not hold it"):
            await other.retire_item(item)
        with pytest.raises(SimulationError, match="cannot hand an item to itself"):
            await me.hand_over(item, 1)
        assert await me.items() == (item,)
        assert env.items.transfers == env.items.retired == 0

    await main(*sim)


@pytest.mark.parametrize(
    "reach",
    [-1.0, -1e-300, math.nan, math.inf],
    ids=["negative", "tiny-negative", "nan", "inf"],
)
def test_reach_must_be_finite_and_not_negative(reach: float) -> None:
    env = Environment()
    env.add_robot(1, Pose(0, 0))
    with pytest.raises(SimulationError, match=r"reach must be a finite number >= 0, got"):
        hands(env, 1, VirtualClock(), reach=reach)


def test_reach_defaults_to_the_same_spot_and_shows_in_repr() -> None:
    env = Environment()
    env.add_robot(1, Pose(0, 0))
    assert hands(env, 1, VirtualClock()).reach == 1e-6
    zero = hands(env, 1, VirtualClock(), reach=0)
    assert zero.reach == 0.0
    assert "reach=0)" in repr(zero)
