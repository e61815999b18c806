"""The simulated middleware on virtual time: exact durations, fatigue, concurrency."""

from __future__ import annotations

import asyncio
import math
import random
from typing import Any

import pytest

import cas_async
from cas_async import (
    ConstantSpeed,
    Decelerating,
    Middleware,
    Pose,
    RobotStateError,
    ScaledClock,
    SimulationError,
    UnknownRobotError,
    VirtualClock,
)
from cas_async.sim import Environment, Motion, SimulatedMiddleware
from tests.sim.conftest import Sim

PI = math.pi


@pytest.mark.cas_virtual
async def test_a_move_ends_exactly_after_its_closed_form_duration(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> tuple[float, Pose, Pose]:
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=PI / 2, speed_profile=ConstantSpeed(2))
        reached = await mw.move_to(0, 10)  # a quarter turn in 1 s, then 10 at 2 in 5 s
        return clock.now(), reached, mw.pose()

    now, reached, pose = await main(*sim)
    assert now == 6.0
    assert reached == pose == Pose(0, 10, PI / 2)


@pytest.mark.cas_virtual
async def test_the_pose_is_exact_while_the_robot_moves(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> list[Pose]:
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=PI / 2, speed_profile=ConstantSpeed(2))
        move = asyncio.create_task(mw.move_to(0, 10))
        seen = []
        for t in (0.5, 3.5, 6.0, 9.0):
            await clock.sleep_until(t)
            seen.append(mw.pose())
        await move
        return seen

    rotating, translating, arrived, later = await main(*sim)
    assert (rotating.x, rotating.y, rotating.heading) == pytest.approx((0, 0, PI / 4))
    assert (translating.x, translating.y) == pytest.approx((0, 5))
    assert arrived == later == Pose(0, 10, PI / 2)


@pytest.mark.cas_virtual
async def test_rotate_to_takes_the_short_way_at_the_turn_rate(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> tuple[float, Pose]:
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=0.5, speed_profile=ConstantSpeed(1))
        pose = await mw.rotate_to(-PI / 2)
        return clock.now(), pose

    now, pose = await main(*sim)
    assert now == pytest.approx(PI)
    assert pose == Pose(0, 0, -PI / 2)


@pytest.mark.cas_virtual
async def test_fatigue_carries_across_moves_until_the_profile_is_replaced(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> list[object]:
        mw = SimulatedMiddleware(
            env, 1, clock, turn_rate=math.inf, speed_profile=Decelerating(5, 1, 1)
        )
        log: list[object] = []
        await mw.move_to(8, 0)  # 5t - t^2/2 = 8: 2 s, leaving speed 3
        log += [clock.now(), mw.speed_profile]
        await mw.move_to(14, 0)  # from speed 3: 4 in 2 s to the floor, then 2 at 1
        log += [clock.now(), mw.speed_profile]
        mw.speed_profile = ConstantSpeed(5)  # e.g. the load was handed over
        await mw.move_to(4, 0)
        log += [clock.now(), mw.speed_profile]
        return log

    assert await main(*sim) == [
        2.0,
        Decelerating(3, 1, 1),
        6.0,
        Decelerating(1, 1, 1),
        8.0,
        ConstantSpeed(5),
    ]


@pytest.mark.cas_virtual
async def test_rotation_does_not_age_the_profile(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> object:
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=1.0, speed_profile=Decelerating(5, 1, 1))
        await mw.rotate_to(2.0)
        return mw.speed_profile

    assert await main(*sim) == Decelerating(5, 1, 1)


@pytest.mark.cas_virtual
async def test_a_profile_set_during_a_move_wins_over_ageing(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> tuple[object, float]:
        mw = SimulatedMiddleware(
            env, 1, clock, turn_rate=math.inf, speed_profile=Decelerating(5, 1, 1)
        )
        move = asyncio.create_task(mw.move_to(8, 0))
        await clock.sleep_until(1.0)
        mw.speed_profile = ConstantSpeed(4)  # applies to the next move only
        await move
        return mw.speed_profile, clock.now()

    assert await main(*sim) == (ConstantSpeed(4), 2.0)


def test_many_robots_move_concurrently_and_each_ends_on_time() -> None:
    rng = random.Random(7)
    plans = {
        robot_id: (
            Pose(rng.uniform(0, 50), rng.uniform(0, 50), rng.uniform(-PI, PI)),
            (rng.uniform(0, 50), rng.uniform(0, 50)),
            rng.uniform(0.5, 3.0),
            Decelerating(rng.uniform(2, 5), rng.uniform(0, 1), 1.0),
        )
        for robot_id in range(200)
    }

    async def main() -> tuple[dict[int, tuple[float, Pose]], Environment]:
        env, clock = Environment(), VirtualClock()
        for robot_id, (pose, *_) in plans.items():
            env.add_robot(robot_id, pose)

        async def drive(robot_id: int) -> tuple[float, Pose]:
            _, (x, y), turn_rate, profile = plans[robot_id]
            mw = SimulatedMiddleware(
                env, robot_id, clock, turn_rate=turn_rate, speed_profile=profile
            )
            reached = await mw.move_to(x, y)
            return clock.now(), reached

        async with asyncio.TaskGroup() as group:
            tasks = {rid: group.create_task(drive(rid)) for rid in plans}
        return {rid: task.result() for rid, task in tasks.items()}, env

    results, env = cas_async.run(main(), virtual=True)
    for robot_id, (start, (x, y), turn_rate, profile) in plans.items():
        expected = Motion.straight_to(start, x, y, turn_rate=turn_rate, profile=profile)
        finished, reached = results[robot_id]
        assert finished == pytest.approx(expected.duration, abs=1e-9)
        assert reached == expected.end
    snapshot = env.positions_at(1e6).as_dict()
    assert all(snapshot[rid] == plans[rid][1] for rid in plans)


@pytest.mark.cas_virtual
async def test_robots_within_sees_the_other_robots_now(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> list[list[int]]:
        env.add_robot(2, Pose(10, 0))
        env.add_robot(3, Pose(-1, 0), mobile=False)
        me = SimulatedMiddleware(env, 1, clock, turn_rate=1, speed_profile=ConstantSpeed(1))
        other = SimulatedMiddleware(
            env, 2, clock, turn_rate=math.inf, speed_profile=ConstantSpeed(1)
        )
        move = asyncio.create_task(other.move_to(10, 10))
        seen = [(await me.robots_within(10.0)).ids.tolist()]
        await clock.sleep_until(5.0)
        seen.append((await me.robots_within(10.0)).ids.tolist())
        await move
        return seen

    assert await main(*sim) == [[3, 2], [3]]


@pytest.mark.cas_virtual
async def test_a_second_move_while_moving_is_refused(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> None:
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=1, speed_profile=ConstantSpeed(1))
        move = asyncio.create_task(mw.move_to(5, 0))
        await clock.sleep(1.0)
        with pytest.raises(RobotStateError, match="robot 1 is already moving"):
            await mw.rotate_to(1.0)
        await move
        assert mw.pose() == Pose(5, 0, 0)

    await main(*sim)


@pytest.mark.cas_virtual
async def test_an_immobile_robot_only_accepts_moves_that_change_nothing(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> None:
        env.add_robot(9, Pose(2, 2, 1.0), mobile=False)
        mw = SimulatedMiddleware(env, 9, clock, turn_rate=1, speed_profile=ConstantSpeed(1))
        assert await mw.move_to(2, 2) == Pose(2, 2, 1.0)
        with pytest.raises(SimulationError, match="robot 9 is immobile"):
            await mw.move_to(3, 2)
        with pytest.raises(SimulationError, match="robot 9 is immobile"):
            await mw.rotate_to(0.0)
        assert clock.now() == 0.0

    await main(*sim)


def test_it_runs_on_scaled_real_time_too() -> None:
    async def main() -> tuple[float, Pose]:
        env, clock = Environment(), ScaledClock(time_factor=1e6)
        env.add_robot(1, Pose(0, 0))
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=1, speed_profile=ConstantSpeed(100))
        reached = await mw.move_to(100, 0)  # 1 simulated second: 1 microsecond real
        return clock.now(), reached

    now, reached = cas_async.run(main(), use_uvloop=False)
    assert now >= 1.0
    assert reached == Pose(100, 0, 0)


def test_it_is_a_middleware() -> None:
    env = Environment()
    env.add_robot(1, Pose(0, 0))
    mw = SimulatedMiddleware(env, 1, VirtualClock(), turn_rate=2, speed_profile=ConstantSpeed(1))
    assert isinstance(mw, Middleware)
    assert mw.robot_id == 1
    assert mw.turn_rate == 2
    assert "robot_id=1" in repr(mw)


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"robot_id": 5}, UnknownRobotError, "robot 5 is not in the environment"),
        ({"turn_rate": 0.0}, SimulationError, "turn_rate must be > 0"),
        ({"turn_rate": math.nan}, SimulationError, "turn_rate must be > 0"),
        ({"speed_profile": 3.0}, SimulationError, "speed_profile must be a SpeedProfile"),
    ],
    ids=["unknown-robot", "zero-turn-rate", "nan-turn-rate", "not-a-profile"],
)
def test_invalid_construction(kwargs: dict[str, Any], error: type[Exception], message: str) -> None:
    env = Environment()
    env.add_robot(1, Pose(0, 0))
    arguments: dict[str, Any] = {
        "robot_id": 1,
        "turn_rate": 1.0,
        "speed_profile": ConstantSpeed(1),
    } | kwargs
    with pytest.raises(error, match=message):
        SimulatedMiddleware(env, clock=VirtualClock(), **arguments)


@pytest.mark.cas_virtual
async def test_non_finite_targets_are_refused(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> None:
        mw = SimulatedMiddleware(env, 1, clock, turn_rate=1, speed_profile=ConstantSpeed(1))
        with pytest.raises(SimulationError, match="x must be a finite number"):
            await mw.move_to(math.nan, 0)
        with pytest.raises(SimulationError, match="heading must be a finite number"):
            await mw.rotate_to(math.inf)
        with pytest.raises(SimulationError, match="radius must be >= 0"):
            await mw.robots_within(-1)

    await main(*sim)
