"""The simulator's seams for runs across processes: motions as numbers, watched; items elsewhere."""

from __future__ import annotations

import asyncio
import math
import time

import pytest

from cas_async import (
    ConstantSpeed,
    Decelerating,
    Pose,
    Robot,
    ScaledClock,
    SimulationError,
    Swarm,
    VirtualClock,
)
from cas_async.sim import Environment, Motion, SimulatedMiddleware
from cas_async.transport import MemoryTransport
from tests.stacks import STACK_MESSAGES, Recorder


@pytest.mark.parametrize(
    "motion",
    [
        Motion.standing(Pose(1.5, -2.25, 0.5)),
        Motion.turn_to(Pose(0, 0, 0), 2.0, turn_rate=math.pi),
        Motion.straight_to(Pose(1, 2, 0.3), 7.5, -3.25, turn_rate=3.0, profile=ConstantSpeed(2.0)),
        Motion.straight_to(
            Pose(0, 0, 0), 30, 40, turn_rate=1.0, profile=Decelerating(3.0, 0.2, 0.5)
        ),
    ],
)
def test_a_motion_as_numbers_gives_every_pose_back_exactly(motion: Motion) -> None:
    copy = Motion.from_numbers(motion.to_numbers())
    assert copy.duration == motion.duration
    for k in range(0, 101):
        elapsed = motion.duration * k / 100 if motion.duration else k / 10
        assert copy.pose_at(elapsed) == motion.pose_at(elapsed)
        assert copy.travelled(elapsed) == motion.travelled(elapsed)


@pytest.mark.parametrize("numbers", [[], [0.0] * 9, [0.0] * 11, [0.0] * 12])
def test_numbers_that_are_no_motion_are_refused(numbers: list[float]) -> None:
    with pytest.raises(SimulationError, match="10 numbers and 3 per phase"):
        Motion.from_numbers(numbers)


def test_motions_with_the_same_phases_share_their_profile_and_keep_its_bits() -> None:
    # A swarm's motions share a few profiles: each is built and checked once.
    start = Pose(0, 0, 0)
    profile = Decelerating(3.0, 0.2, 0.5)
    one, two = (
        Motion.from_numbers(Motion.straight_to(start, x, 0, turn_rate=1.0, profile=profile)
                            .to_numbers())
        for x in (30.0, 31.0)
    )  # fmt: skip
    assert one.profile is not None
    assert one.profile is two.profile
    # -0.0 and 0.0 are equal, not the same bits: they are two profiles.
    numbers = Motion.straight_to(
        start, 5, 0, turn_rate=1.0, profile=ConstantSpeed(2.0)
    ).to_numbers()
    assert numbers[-1] == 0.0
    negative = Motion.from_numbers([*numbers[:-1], -0.0]).profile
    positive = Motion.from_numbers(numbers).profile
    assert negative is not None
    assert positive is not None
    assert math.copysign(1.0, negative.phases()[-1].acceleration) == -1.0
    assert math.copysign(1.0, positive.phases()[-1].acceleration) == 1.0


@pytest.mark.parametrize("repeat", [1, 2], ids=["first", "again"])
def test_phases_that_break_the_profile_contract_are_refused_every_time(repeat: int) -> None:
    numbers = Motion.straight_to(Pose(0, 0, 0), 5, 0, turn_rate=1.0, profile=ConstantSpeed(2.0))
    broken = [*numbers.to_numbers()[:-3], 1.0, 2.0, 0.0]  # the last phase is no cruise
    for _ in range(repeat):
        with pytest.raises(SimulationError, match="the last phase must be a cruise"):
            Motion.from_numbers(broken)


@pytest.mark.cas_virtual
async def test_watchers_see_every_motion_and_halt_and_a_replica_follows_exactly() -> None:
    clock = VirtualClock()
    world, replica = Environment(), Environment()
    for env in (world, replica):
        env.add_robot(1, Pose(0, 0, 0))
        env.add_robot(2, Pose(5, 5, 0))
    seen: list[tuple[int, float]] = []

    def publish(robot_id: int, motion: Motion, start: float) -> None:
        seen.append((robot_id, start))
        replica.start_motion(robot_id, Motion.from_numbers(motion.to_numbers()), start)

    world.watch_motions(publish)
    driver = SimulatedMiddleware(
        world, 1, clock, turn_rate=math.pi, speed_profile=ConstantSpeed(1.0)
    )
    moving = asyncio.ensure_future(driver.move_to(10, 0))
    await clock.sleep(3.0)
    moving.cancel()  # halted mid-way: the halt is a motion too
    with pytest.raises(asyncio.CancelledError):
        await moving
    assert [robot for robot, _ in seen] == [1, 1]
    for t in (0.0, 1.0, 2.5, 3.0, 100.0):
        assert replica.pose_at(1, t) == world.pose_at(1, t)
    assert replica.within(2, 20.0, 50.0).ids.tolist() == world.within(2, 20.0, 50.0).ids.tolist()


def test_a_scaled_clock_started_at_a_wall_instant_reads_the_time_since_then() -> None:
    async def main() -> tuple[float, float]:
        early, late = ScaledClock(10.0), ScaledClock(10.0)
        early.start_at_wall(time.time() - 1.0)  # one wall second ago: 10 simulated seconds
        late.start_at_wall(time.time() + 1.0)
        return early.now(), late.now()

    early, late = asyncio.run(main())
    assert 9.0 < early < 12.0
    assert -11.0 < late < -9.0


def test_a_started_scaled_clock_cannot_be_aligned() -> None:
    async def main() -> None:
        clock = ScaledClock(2.0)
        clock.start()
        with pytest.raises(Exception, match="started already"):
            clock.start_at_wall(time.time())

    asyncio.run(main())


@pytest.mark.cas_virtual
async def test_a_swarm_opened_can_be_reached_before_it_starts() -> None:
    transport = MemoryTransport()
    stacks = {rid: [Recorder(), Recorder()] for rid in (1, 2)}
    swarm = Swarm(
        Robot(rid, stack, transport=transport, messages=STACK_MESSAGES)
        for rid, stack in stacks.items()
    )
    await swarm.open()
    try:
        assert all(robot.state.name == "OPEN" for robot in swarm)
        assert all(robot.address == ("memory", robot.robot_id) for robot in swarm)
        swarm.start()
        assert all(robot.state.name == "RUNNING" for robot in swarm)
    finally:
        await swarm.__aexit__(None, None, None)
    assert all(robot.state.name == "STOPPED" for robot in swarm)
