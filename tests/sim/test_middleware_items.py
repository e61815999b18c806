"""Items through the simulated middleware, on virtual time: hand-overs between robots."""

from __future__ import annotations

import asyncio
import math

import pytest

from cas_async import UnknownRobotError, VirtualClock
from cas_async.sim import (
    ConstantSpeed,
    Environment,
    ItemEventKind,
    Middleware,
    Pose,
    SimulatedMiddleware,
    SimulationError,
)
from tests.sim.virtual import virtual


def middleware(
    env: Environment, robot_id: int, clock: VirtualClock, **kwargs: float
) -> SimulatedMiddleware:
    """A robot that turns instantly and drives at 1 m/s."""
    return SimulatedMiddleware(
        env, robot_id, clock, turn_rate=math.inf, speed_profile=ConstantSpeed(1), **kwargs
    )


def test_the_middleware_declares_the_item_methods() -> None:
    assert {"items", "create_item", "hand_over", "retire_item"} <= Middleware.__abstractmethods__


def test_a_robot_carries_an_item_to_another_and_hands_it_over() -> None:
    async def main(env: Environment, clock: VirtualClock) -> list[object]:
        env.items.subscribe(lambda _: env.items.check())
        env.add_robot(2, Pose(5, 0))
        carrier, keeper = middleware(env, 1, clock), middleware(env, 2, clock)
        item = carrier.create_item()
        log: list[object] = [carrier.items(), keeper.items()]
        with pytest.raises(SimulationError, match=r"they are 5\.0 apart"):
            carrier.hand_over(item, 2)
        await carrier.move_to(5, 0)
        carrier.hand_over(item, 2)
        log += [clock.now(), carrier.items(), keeper.items()]
        await keeper.move_to(5, 2)
        keeper.retire_item(item)
        log += [keeper.items(), [(e.t, e.kind, e.robot) for e in env.items.history(item)]]
        return log

    assert virtual(main) == [
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


def test_a_hand_over_happens_mid_move_where_the_robots_are_then() -> None:
    async def main(env: Environment, clock: VirtualClock) -> tuple[float, float, tuple[int, ...]]:
        env.add_robot(2, Pose(10, 0))
        walker = middleware(env, 1, clock)
        keeper = middleware(env, 2, clock, reach=0.5)
        item = keeper.create_item()
        move = asyncio.create_task(walker.move_to(20, 0))  # passes robot 2 at t = 10
        await clock.sleep_until(9.0)
        with pytest.raises(SimulationError, match=r"beyond the reach of 0\.5"):
            keeper.hand_over(item, 1)  # 1 m apart
        await clock.sleep_until(9.5)
        keeper.hand_over(item, 1)  # exactly 0.5 m apart: within reach
        moved_on = walker.pose().x
        await move
        return clock.now(), moved_on, walker.items()

    assert virtual(main) == (20.0, 9.5, (1,))


def test_items_are_listed_in_the_order_received() -> None:
    async def main(env: Environment, clock: VirtualClock) -> tuple[int, ...]:
        env.add_robot(2, Pose(0, 0))
        me, other = middleware(env, 1, clock), middleware(env, 2, clock)
        first, second = other.create_item(), me.create_item()
        await clock.sleep(1.0)
        other.hand_over(first, 1)
        third = me.create_item()
        assert (first, second, third) == (1, 2, 3)
        return me.items()

    assert virtual(main) == (2, 1, 3)


def test_refused_item_calls_leave_everything_in_place() -> None:
    async def main(env: Environment, clock: VirtualClock) -> None:
        env.add_robot(2, Pose(0, 0))
        me, other = middleware(env, 1, clock), middleware(env, 2, clock)
        item = me.create_item()
        with pytest.raises(UnknownRobotError, match="robot 7 is not in the environment"):
            me.hand_over(item, 7)
        with pytest.raises(SimulationError, match="robot 2 does not hold it"):
            other.hand_over(item, 1)
        with pytest.raises(SimulationError, match="robot 2 does not hold it"):
            other.retire_item(item)
        with pytest.raises(SimulationError, match="cannot hand an item to itself"):
            me.hand_over(item, 1)
        assert me.items() == (item,)
        assert env.items.transfers == env.items.retired == 0

    virtual(main)


@pytest.mark.parametrize(
    "reach",
    [-1.0, -1e-300, math.nan, math.inf],
    ids=["negative", "tiny-negative", "nan", "inf"],
)
def test_reach_must_be_finite_and_not_negative(reach: float) -> None:
    env = Environment()
    env.add_robot(1, Pose(0, 0))
    with pytest.raises(SimulationError, match=r"reach must be a finite number >= 0, got"):
        middleware(env, 1, VirtualClock(), reach=reach)


def test_reach_defaults_to_the_same_spot_and_shows_in_repr() -> None:
    env = Environment()
    env.add_robot(1, Pose(0, 0))
    assert middleware(env, 1, VirtualClock()).reach == 1e-6
    zero = middleware(env, 1, VirtualClock(), reach=0)
    assert zero.reach == 0.0
    assert "reach=0," in repr(zero)
