"""The Environment with a latency: others seen L late, items that take L each way.

Every test runs on virtual time with a clock started at loop time 0, so simulated
instants are exact and a test can wait for any one of them.
"""

from __future__ import annotations

import asyncio
import math
import random
from collections.abc import Callable

import pytest

from cas_async import Pose, SimulationError, UnknownRobotError, VirtualClock
from cas_async.sim import Environment, Motion, SimulatedHands
from cas_async.sim._items import ID_SPAN
from tests.sim.latency_support import (
    CREATED,
    REFUSED,
    RETURNED,
    SENT,
    TRANSFERRED,
    L,
    drive,
    seen,
    started_clock,
    story,
    until,
    world,
)

# -- configuration -------------------------------------------------------------------------


@pytest.mark.parametrize("latency", [-0.1, math.inf, math.nan])
def test_a_latency_that_is_no_duration_is_refused(latency: float) -> None:
    with pytest.raises(ValueError, match="latency must be a finite number >= 0"):
        Environment(latency=latency, clock=VirtualClock())


def test_a_latency_needs_the_robots_clock() -> None:
    with pytest.raises(ValueError, match="needs the robots' clock"):
        Environment(latency=0.1)


# -- what robots see -----------------------------------------------------------------------


@pytest.mark.cas_virtual
async def test_others_see_a_motion_a_latency_after_it_started_carried_on_to_now() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (10, 0))
    await until(clock, 1.0)
    drive(env, 2, 1.0, 20, 0)
    assert seen(env, 1, 1.0) == {2: (10.0, 0.0)}
    await until(clock, 1.25)
    assert seen(env, 1, 1.25) == {2: (10.0, 0.0)}  # not seen yet: still standing
    assert env.pose_at(2, 1.25) == Pose(10.25, 0.0, 0.0)  # where it really is
    assert env.positions_at(1.25).as_dict()[2] == (10.25, 0.0)  # the world's truth
    await until(clock, 1.0 + L)
    assert seen(env, 1, 1.0 + L) == {2: (10.0 + L, 0.0)}  # seen, from where it started
    await until(clock, 3.0)
    assert seen(env, 1, 3.0) == {2: (12.0, 0.0)}


@pytest.mark.cas_virtual
async def test_a_robot_sees_the_others_from_where_it_really_is() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (10, 0))
    await until(clock, 1.0)
    drive(env, 2, 1.0, 20, 0)
    await until(clock, 1.1)
    # Robot 2 is 10.1 from robot 1 (it knows where it is); robot 1 is where it stands.
    assert len(env.within(2, 10.05, 1.1)) == 0
    assert seen(env, 2, 1.1) == {1: (0.0, 0.0)}
    assert len(env.within(1, 10.05, 1.1)) == 1  # robot 1 still sees it at 10


@pytest.mark.cas_virtual
async def test_a_halt_is_seen_late_the_motion_before_it_carried_on_meanwhile() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (10, 0))
    await until(clock, 1.0)
    drive(env, 2, 1.0, 20, 0)
    await until(clock, 2.0)
    assert env.halt(2, 2.0) == Pose(11.0, 0.0, 0.0)
    await until(clock, 2.3)
    assert seen(env, 1, 2.3)[2] == pytest.approx((11.3, 0.0))  # dead reckoning
    await until(clock, 2.0 + L)
    assert seen(env, 1, 2.0 + L) == {2: (11.0, 0.0)}
    await until(clock, 9.0)
    assert seen(env, 1, 9.0) == {2: (11.0, 0.0)}


@pytest.mark.cas_virtual
async def test_of_motions_closer_than_the_latency_each_is_seen_at_its_turn() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (10, 0))
    await until(clock, 1.0)
    drive(env, 2, 1.0, 20, 0)
    await until(clock, 1.2)
    drive(env, 2, 1.2, 10.2, 5)  # turns left
    await until(clock, 1.0 + L)
    assert seen(env, 1, 1.0 + L)[2] == pytest.approx((10.5, 0.0))  # the first, carried on
    await until(clock, 1.2 + L)
    assert seen(env, 1, 1.2 + L)[2] == pytest.approx((10.2, 0.5))
    assert env.pose_at(2, 1.2 + L).y == pytest.approx(0.5)


@pytest.mark.cas_virtual
async def test_with_many_robots_the_grid_sees_what_the_latency_model_says() -> None:
    clock, rng = started_clock(), random.Random(28)
    poses = [(rng.uniform(0, 30), rng.uniform(0, 30)) for _ in range(80)]
    env = world(clock, *poses, cell_size=3.0)  # >= 64 robots: the grid
    motions: dict[int, list[tuple[float, Motion]]] = {r: [] for r in range(1, 81)}
    for step in range(1, 9):
        t = step * 0.3
        await until(clock, t)
        for robot_id in rng.sample(range(1, 81), 10):
            target = (rng.uniform(0, 30), rng.uniform(0, 30))
            motions[robot_id].append((t, drive(env, robot_id, t, *target)))
        for asker in rng.sample(range(1, 81), 8):
            near = env.within(asker, 4.0, t).as_dict()
            here = env.pose_at(asker, t)
            # An infinite radius evaluates every robot, without the grid.
            everyone = env.within(asker, math.inf, t).as_dict()
            assert near == {
                robot: xy
                for robot, xy in everyone.items()
                if math.hypot(xy[0] - here.x, xy[1] - here.y) <= 4.0
            }
            expected = set()
            for robot_id, (x, y) in enumerate(poses, start=1):
                started = [(s, m) for s, m in motions[robot_id] if s + L <= t]
                if started:
                    since, motion = started[-1]
                    pose = motion.pose_at(t - since)
                    x, y = pose.x, pose.y
                if robot_id != asker and math.hypot(x - here.x, y - here.y) <= 4.0:
                    expected.add(robot_id)
            assert set(near) == expected, (asker, t)


# -- items over the latency ----------------------------------------------------------------


@pytest.mark.cas_virtual
async def test_a_hand_over_leaves_at_t_arrives_at_t_plus_l_and_returns_at_t_plus_2l() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (0.5, 0))
    giver, receiver = SimulatedHands(env, 1, clock, reach=1.0), SimulatedHands(env, 2, clock)
    item = await giver.create_item()
    await until(clock, 1.0)
    handing = asyncio.ensure_future(giver.hand_over(item, 2))
    await asyncio.sleep(0)
    assert env.items.holder(item) is None  # on its way: nobody holds it
    assert (env.items.in_transit, await giver.items(), await receiver.items()) == (1, (), ())
    await until(clock, 1.0 + L)
    assert env.items.holder(item) == 2
    assert not handing.done()  # the giver does not know yet
    await handing
    assert clock.now() == 1.0 + 2 * L
    assert story(env.items) == [(0.0, CREATED, 1), (1.0, SENT, 1), (1.0 + L, TRANSFERRED, 2)]
    assert (env.items.in_transit, env.items.transfers) == (0, 1)


@pytest.mark.parametrize(
    ("refuse", "reason"),
    [
        (lambda env: env.accept_from(2, 3), r"robot 2 does not take items from robot 1 .*\[3\]"),
        (lambda env: env.refuse_from(2, 1), r"robot 2 does not take items from robot 1 .*\[\]"),
        (lambda env: drive(env, 2, 1.2, 5, 0), r"beyond the reach of 1\.0"),
    ],
    ids=["held-out-to-another", "withdrawn-on-the-way", "drove-out-of-reach"],
)
@pytest.mark.cas_virtual
async def test_a_refused_item_is_back_with_its_giver_at_t_plus_2l_and_the_giver_hears_why(
    refuse: Callable[[Environment], object], reason: str
) -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (0.9, 0), (9, 9))
    giver = SimulatedHands(env, 1, clock, reach=1.0)
    item = await giver.create_item()
    await until(clock, 1.0)
    handing = asyncio.ensure_future(giver.hand_over(item, 2))
    await until(clock, 1.2)
    refuse(env)  # after it left, before it arrives
    await until(clock, 1.0 + L)
    assert env.items.holder(item) is None  # refused: on its way back
    with pytest.raises(SimulationError, match=reason):
        await handing
    assert clock.now() == 1.0 + 2 * L
    assert env.items.holder(item) == 1
    assert story(env.items) == [
        (0.0, CREATED, 1),
        (1.0, SENT, 1),
        (1.0 + L, REFUSED, 2),
        (1.0 + 2 * L, RETURNED, 1),
    ]
    assert env.items.transfers == 0


@pytest.mark.cas_virtual
async def test_a_giver_that_moves_as_it_hands_over_is_seen_moving_when_the_item_arrives() -> None:
    # Its motion and its item become visible at the same instant: the motion first.
    clock = started_clock()
    env = world(clock, (0, 0), (0, 0))
    item = env.create_item(1, 0.0)
    await until(clock, 1.0)
    handing = asyncio.ensure_future(env.send_item(item, 1, 2, 1.0, reach=0.4))
    await asyncio.sleep(0)
    drive(env, 1, 1.0, 10, 0)  # seen at 1 + L, 0.5 away by then: beyond the reach
    with pytest.raises(SimulationError, match=r"robot 1 cannot hand .* beyond the reach of 0\.4"):
        await handing


@pytest.mark.cas_virtual
async def test_items_arriving_at_one_instant_are_taken_in_giver_order() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (0, 0), (0, 0), (0, 0))
    items = {giver: env.create_item(giver, 0.0) for giver in (4, 2, 3)}
    await until(clock, 1.0)
    handing = [
        asyncio.ensure_future(env.send_item(items[giver], giver, 1, 1.0, reach=0.1))
        for giver in (4, 2, 3)
    ]
    await asyncio.gather(*handing)
    assert env.items.held_by(1) == (items[2], items[3], items[4])


@pytest.mark.cas_virtual
async def test_item_ids_are_made_by_their_creator() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (0, 0))
    assert env.create_item(2, 0.0) == 2 * ID_SPAN + 1
    assert env.create_item(1, 0.0) == 1 * ID_SPAN + 1
    assert env.create_item(2, 0.0) == 2 * ID_SPAN + 2


@pytest.mark.cas_virtual
async def test_a_hand_over_that_cannot_start_fails_at_once_and_changes_nothing() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (0, 0))
    item = env.create_item(1, 0.0)
    before = len(env.items.events)
    with pytest.raises(SimulationError, match="robot 2 does not hold it"):
        await env.send_item(item, 2, 1, 0.0, reach=1.0)
    with pytest.raises(SimulationError, match="cannot hand an item to itself"):
        await env.send_item(item, 1, 1, 0.0, reach=1.0)
    with pytest.raises(UnknownRobotError, match="robot 7"):
        await env.send_item(item, 1, 7, 0.0, reach=1.0)
    with pytest.raises(SimulationError, match="reach must be >= 0"):
        await env.send_item(item, 1, 2, 0.0, reach=-1.0)
    with pytest.raises(SimulationError, match="must be a finite number"):
        await env.send_item(item, 1, 2, math.inf, reach=1.0)
    assert clock.now() == 0.0
    assert len(env.items.events) == before
    assert env.items.holder(item) == 1


@pytest.mark.cas_virtual
async def test_without_a_latency_a_hand_over_is_atomic() -> None:
    clock = started_clock()
    env = Environment(clock=clock)
    env.add_robot(1, Pose(0, 0, 0))
    env.add_robot(2, Pose(0, 0, 0))
    item = env.create_item(1, 0.0)
    await env.send_item(item, 1, 2, 0.0, reach=0.1)
    assert clock.now() == 0.0
    assert [(e.kind, e.actor) for e in env.items.events] == [(CREATED, 1), (TRANSFERRED, 2)]


@pytest.mark.cas_virtual
async def test_a_giver_that_stops_waiting_does_not_stop_its_item() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (0, 0))
    item = env.create_item(1, 0.0)
    handing = asyncio.ensure_future(env.send_item(item, 1, 2, 0.0, reach=0.1))
    await until(clock, L / 2)
    handing.cancel()
    await asyncio.sleep(5 * L)
    assert handing.cancelled()
    assert env.items.holder(item) == 2
    assert story(env.items)[-1] == (L, TRANSFERRED, 2)


# -- robots leaving ------------------------------------------------------------------------


@pytest.mark.cas_virtual
@pytest.mark.parametrize("leaving", [1, 2], ids=["giver", "receiver"])
async def test_a_robot_with_items_on_their_way_to_or_from_it_cannot_leave(leaving: int) -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (0, 0))
    env.refuse_from(2, 1)
    item = env.create_item(1, 0.0)
    handing = asyncio.ensure_future(env.send_item(item, 1, 2, 0.0, reach=0.1))
    for instant in (L / 2, 1.5 * L):  # on its way there, then refused and on its way back
        await until(clock, instant)
        with pytest.raises(SimulationError, match=rf"items \[{item}\] are on their way"):
            env.remove_robot(leaving)
    with pytest.raises(SimulationError, match="does not take items"):
        await handing
    env.retire_item(item, 1, clock.now())
    env.remove_robot(leaving)  # nothing on its way any more
    assert leaving not in env


@pytest.mark.cas_virtual
async def test_a_robot_that_leaves_before_its_motion_is_seen_is_simply_gone() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (10, 0))
    loop = asyncio.get_running_loop()
    failures: list[dict[str, object]] = []
    loop.set_exception_handler(lambda _loop, context: failures.append(context))
    try:
        drive(env, 2, 0.0, 20, 0)
        await until(clock, L / 2)
        env.remove_robot(2)
        env.add_robot(2, Pose(-3, 0, 0))  # another robot 2: the old motion is not its
        await until(clock, 2 * L)
    finally:
        loop.set_exception_handler(None)
    assert failures == []
    assert seen(env, 1, 2 * L) == {2: (-3.0, 0.0)}


@pytest.mark.cas_virtual
async def test_a_giver_hears_of_a_receiver_that_took_the_item_and_left() -> None:
    clock = started_clock()
    env = world(clock, (0, 0), (0, 0))
    item = env.create_item(1, 0.0)
    handing = asyncio.ensure_future(env.send_item(item, 1, 2, 0.0, reach=0.1))
    await until(clock, L)
    env.retire_item(item, 2, L)
    env.remove_robot(2)
    await asyncio.wait_for(handing, 10.0)
    assert clock.now() == 2 * L
