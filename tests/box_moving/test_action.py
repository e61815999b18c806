"""The Action layer alone: PickUp, Move and Scan on a simulated robot and Floor, on virtual time.

The carries run under LayerHarness (commands from a scripted Coordination
layer); the scan and the queries, whose answers travel to the top of the
stack, in a robot of recording layers.
"""

from __future__ import annotations

import math

import pytest

from apps.box_moving.action import Action
from apps.box_moving.base import ACTION
from apps.box_moving.floor import Floor
from apps.box_moving.gripper import FloorGripper
from apps.box_moving.messages import (
    MESSAGES,
    CarryDone,
    CarryOut,
    Go,
    Locate,
    Located,
    MovedCount,
    Position,
    Ready,
    Release,
    Role,
    Scan,
    ScanResult,
    Side,
    Where,
)
from apps.box_moving.records import Box
from cas_async import ConstantSpeed, Layer, Message, Pose, VirtualClock
from cas_async.sim import Environment, SimulatedMiddleware
from cas_async.testing import LayerHarness, Recorder, Robots, run_until, wait_all_tasks_blocked
from tests.box_moving.helpers import bodies, body, drive, params, sighting

# Robot 1 stands at (0, 5) facing east; object 1 (weight 4) and object 2 (weight
# 14), both of size 1, lie at (5, 5) and (5, 8); the zone is (9, 5), radius 1.5.
LIGHT = sighting(1, 5.0, 5.0, weight=4.0)
HEAVY = sighting(2, 5.0, 8.0, weight=14.0)


def world(clock: VirtualClock) -> tuple[Environment, Floor, Action]:
    environment = Environment()
    environment.add_robot(1, Pose(0.0, 5.0, 0.0))
    environment.add_robot(2, Pose(5.5, 8.0, math.pi))  # at object 2's east side
    boxes = [Box(1, 5.0, 5.0, 4.0, 1.0, 9.0, 5.0), Box(2, 5.0, 8.0, 14.0, 1.0, 9.0, 5.0)]
    floor = Floor(environment, boxes, ((9.0, 5.0), 1.5), {1: 10.0, 2: 6.0}, slack=1e-6)
    middleware = SimulatedMiddleware(
        environment, 1, clock, turn_rate=math.pi, speed_profile=ConstantSpeed(1.0)
    )
    action = Action(params(peers=(2,)), middleware, FloorGripper(floor, 1, clock))
    return environment, floor, action


@pytest.mark.cas_virtual
async def test_a_solo_carry_picks_up_moves_and_puts_down_in_the_drop_spot() -> None:
    clock = VirtualClock()
    _, floor, action = world(clock)
    async with LayerHarness(action, level=ACTION, height=4, messages=MESSAGES, clock=clock) as h:
        h.from_above(CarryOut(LIGHT, Role.SOLO, Side.WEST, 0.8))
        await run_until(lambda: len(h.sent_up) == 2, timeout=60)
        assert floor.is_moved(1)
        # 4.5 to the west side at speed 1, lift 1 s, 4 loaded at 0.8, put down 1 s
        assert clock.now() == pytest.approx(4.5 + 1 + 4 / 0.8 + 1)
        assert bodies(h.sent_up) == [body(CarryDone(1)), body(MovedCount(1))]
        assert floor.position(1, clock.now()) == pytest.approx((9.0, 5.0))
        assert action.carry is None


@pytest.mark.cas_virtual
async def test_a_joint_carry_waits_for_the_partner_between_legs() -> None:
    clock = VirtualClock()
    environment, floor, action = world(clock)
    floor.lift(2, 2, Side.EAST, 1, 0.0)  # the partner is in place and lifted already
    async with LayerHarness(action, level=ACTION, height=4, messages=MESSAGES, clock=clock) as h:
        h.from_above(CarryOut(HEAVY, Role.LEADER, Side.WEST, 0.5, partner=2))
        await run_until(lambda: h.sent_up, timeout=60)
        assert bodies(h.sent_up) == [body(Ready(2, 0))]  # lifted, facing the drop spot
        assert floor.lifters() == {1, 2}
        at = clock.now() + 0.2
        # The helper's Action would start the same leg at the same instant.
        drive(environment, 2, 9.5, 5.0, at, speed=0.5)
        h.from_above(Go(2, 0, 9.0, 5.0, at))
        await run_until(lambda: len(h.sent_up) == 2, timeout=60)
        arrived = at + 5.0 / 0.5  # from (5, 8) to (9, 5) is 3-4-5: no turn, it faces there
        assert clock.now() == pytest.approx(arrived)
        assert bodies(h.sent_up)[-1] == body(Ready(2, 1))
        assert floor.position(2, arrived) == pytest.approx((9.0, 5.0))
        h.from_above(Release(2, arrived + 0.2))
        await run_until(lambda: len(h.sent_up) == 3, timeout=60)
        assert clock.now() == pytest.approx(arrived + 0.2 + 1.0)
        floor.put_down(2, 2, clock.now())  # the helper puts down its side too
        assert floor.is_moved(2)
        assert bodies(h.sent_up)[-1] == body(CarryDone(2))
        floor.audit(clock.now())


class Asker(Layer):
    """Asks the layer below: stands where Coordination does."""

    async def ask(self, msg: Message) -> Message:
        return await self.request_down(msg)


@pytest.mark.cas_virtual
async def test_scan_and_queries_are_answered_from_the_floor_and_the_environment() -> None:
    clock = VirtualClock()
    _, floor, action = world(clock)
    top, asker = Recorder(), Asker()
    robots = Robots(messages=MESSAGES)
    try:
        await robots.start(1, [top, Recorder(), asker, action], clock=clock)
        floor.claim(2, 2, 0.0)  # robot 2's selection: not for robot 1's eyes
        asker.send_to_layer(ACTION, Scan())
        await wait_all_tasks_blocked()
        (scan,) = top.of_type(ScanResult)
        assert (scan.x, scan.y, scan.moved) == (0.0, 5.0, 0)
        assert [seen.obj for seen in scan.objects] == [1]
        assert (scan.objects[0].drop_x, scan.objects[0].drop_y) == (9.0, 5.0)
        where = await asker.ask(Where())
        assert isinstance(where, Position)
        assert (where.x, where.y, where.heading) == (0.0, 5.0, 0.0)
        others = await asker.ask(Locate())
        assert isinstance(others, Located)
        assert (others.ids, others.xs, others.ys) == ([2], [5.5], [8.0])
    finally:
        await robots.aclose()
