"""An interaction range: what no robot senses, sends or hands farther than (``[network] range``).

* a range query wider than the range, and a hand-over reaching farther, are errors
  naming the range;
* a datagram to a robot beyond the range is lost as on a radio, counted at the sender
  as ``transport.out_of_range``; a broadcast reaches the robots within it; exactly the
  robots a range query lists are reached, to the last bit;
* a robot's declared top speed bounds every motion of it;
* the Fire Brigade declares its range in the scale scenarios: the same run as without.
"""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import numpy as np
import pytest

from cas_async import (
    ConfigurationError,
    ConstantSpeed,
    Decelerating,
    Layer,
    MemoryTransport,
    Message,
    Pose,
    Robot,
    SimulationError,
    Swarm,
    VirtualClock,
)
from cas_async.scenario import RunStatus
from cas_async.sim import Environment, Motion, RangedTransport
from cas_async.testing import run_scenario_file

ROOT = Path(__file__).resolve().parents[2]
SCALE_250 = ROOT / "apps" / "fire_brigade" / "scenarios" / "scale_250.toml"


def ranged_world(limit: float = 10.0) -> Environment:
    env = Environment(interaction_range=limit)
    env.add_robot(1, Pose(0, 0))
    env.add_robot(2, Pose(10, 0))  # exactly at the range: inclusive
    env.add_robot(3, Pose(10.000001, 0.5))
    return env


def test_a_query_wider_than_the_range_is_refused_naming_it() -> None:
    env = ranged_world()
    assert env.within(1, 10.0, 0.0).ids.tolist() == [2]
    with pytest.raises(SimulationError, match=r"within 10\.5; .*interaction range is 10 "):
        env.within(1, 10.5, 0.0)
    with pytest.raises(SimulationError, match=r"\[network\] range"):
        env.within(1, math.inf, 0.0)


def test_a_hand_over_beyond_the_range_is_refused_naming_it() -> None:
    env = ranged_world(limit=0.5)
    item = env.create_item(1, 0.0)
    with pytest.raises(SimulationError, match=r"reach of 1, beyond .* interaction range of 0\.5"):
        env.hand_over(item, 1, 2, 0.0, reach=1.0)
    assert env.items.held_by(1) == (item,)


def test_in_range_is_what_a_query_lists_to_the_last_bit() -> None:
    rng = np.random.default_rng(7)
    env = Environment(interaction_range=3.0)
    for robot in range(200):
        x, y = rng.uniform(0, 30, size=2)
        env.add_robot(robot, Pose(float(x), float(y)))
    for robot in range(0, 200, 7):
        listed = set(env.within(robot, 3.0, 0.0).ids.tolist())
        reached = {
            other for other in range(200) if other != robot and env.in_range(robot, other, 0.0)
        }
        assert listed == reached


def test_without_a_range_everyone_is_in_range() -> None:
    env = Environment()
    env.add_robot(1, Pose(0, 0))
    env.add_robot(2, Pose(1e6, 0))
    assert env.in_range(1, 2, 0.0)
    assert env.interaction_range is None


@pytest.mark.parametrize("limit", [0.0, -1.0, math.nan, math.inf])
def test_a_range_is_a_finite_number_above_zero(limit: float) -> None:
    with pytest.raises(ValueError, match="interaction_range must be a finite number > 0"):
        Environment(interaction_range=limit)


def test_a_motion_faster_than_the_robot_s_top_speed_is_refused() -> None:
    env = Environment()
    env.add_robot(1, Pose(0, 0), top_speed=2.0)
    env.start_motion(
        1, Motion.straight_to(Pose(0, 0), 5, 0, turn_rate=1.0, profile=ConstantSpeed(2.0)), 0.0
    )
    with pytest.raises(SimulationError, match=r"up to 3 units/s, faster than its top speed of 2"):
        env.start_motion(
            1,
            Motion.straight_to(
                Pose(0, 0), 0, 5, turn_rate=1.0, profile=Decelerating(3.0, 1.0, 1.0)
            ),
            0.0,
        )
    assert env.top_speed(1) == 2.0
    env.add_robot(2, Pose(1, 1), mobile=False)
    assert env.top_speed(2) == 0.0
    with pytest.raises(ConfigurationError, match="top_speed must be a finite number >= 0"):
        env.add_robot(3, Pose(2, 2), top_speed=-1.0)


class Ping(Message):
    n: int


class Talker(Layer):
    """Sends a Ping to ``to`` (or broadcasts) once; records what it hears."""

    def __init__(self, to: int | None) -> None:
        self.to = to
        self.heard: list[int] = []
        self.sent = False

    async def inner_process(self) -> None:
        if not self.sent:
            self.sent = True
            if self.to is None:
                self.broadcast(Ping(self.robot_id))
            else:
                self.send(self.to, Ping(self.robot_id))

    async def handle_msg(self, msg: Message) -> None:
        match msg:
            case Ping(n=n):
                self.heard.append(n)


@pytest.mark.cas_virtual
@pytest.mark.parametrize("to", [3, None], ids=["to-one", "broadcast"])
async def test_a_datagram_beyond_the_range_is_lost_and_counted_at_the_sender(
    to: int | None,
) -> None:
    clock = VirtualClock()
    env = ranged_world()
    transport = RangedTransport(MemoryTransport(clock=clock), env, clock)
    layers = {robot: Talker(to if robot == 1 else -1) for robot in (1, 2, 3)}
    for robot in (2, 3):
        layers[robot].sent = True  # only robot 1 talks
    robots = [Robot(r, [layers[r]], transport=transport, clock=clock) for r in (1, 2, 3)]
    async with Swarm(robots):
        await asyncio.sleep(1.0)
    assert layers[3].heard == []  # 10.000001 + away: beyond
    if to is None:
        assert layers[2].heard == [1]  # exactly at the range: reached
        assert robots[0].dropped == {}  # a broadcast goes to those in range
    else:
        assert robots[0].dropped == {"transport.out_of_range": 1}


@pytest.mark.slow
def test_the_fire_brigade_s_scale_scenario_runs_the_same_with_its_range() -> None:
    ranged = run_scenario_file(SCALE_250)
    unranged = run_scenario_file(SCALE_250, "network.range=1e9")
    assert ranged.result.status is RunStatus.COMPLETED
    assert ranged.result.protocol_errors == {}  # nothing was out of range
    assert ranged.result.makespan == unranged.result.makespan
    assert np.array_equal(ranged.trace.positions, unranged.trace.positions)
