"""What a worker sees of the others' robots (``ProcessNetwork``), with an interaction range.

A motion another worker's robot starts at ``t`` is seen here at ``t + L``. A robot
out of sight (hidden: no worker of its own robots can meet it) keeps the latest
motion it was seen to start, and is placed by it when it comes into sight. A
worker that ran ahead of one it does not depend on hears that one's motions after
their instant: for a hidden robot they are kept the same way (the newest by its
time and count, in whatever order they come); for a robot in sight that would be
a fault of the protocol, and it is an error, never a silent divergence.
"""

from __future__ import annotations

import asyncio

import pytest

from cas_async import Pose, SimulationError, VirtualClock, VirtualTimeLoop
from cas_async.scenario._processes._network import ProcessNetwork
from cas_async.scenario._processes._observer import MotionRecord, Observation
from cas_async.sim import Environment, Motion

L = 0.005
OWN, OTHER = 1, 2  # robot 1 runs on worker 0 (here), robot 2 on worker 1


def world() -> tuple[Environment, ProcessNetwork]:
    clock = VirtualClock()
    clock.start()  # simulated time 0 is now
    environment = Environment(latency=L, clock=clock, interaction_range=10.0)
    environment.add_robot(OWN, Pose(0, 0))
    environment.add_robot(OTHER, Pose(50, 0))
    network = ProcessNetwork({OWN: 0, OTHER: 1}, 0, L, clock, environment)
    environment.set_local({OWN}, network)
    return environment, network


def started(t: float, n: int, x: float) -> MotionRecord:
    """Robot OTHER started its ``n``-th motion at ``t``: standing at ``(x, 0)``."""
    return MotionRecord(t, OTHER, n, Motion.standing(Pose(x, 0)).to_numbers())


def loop() -> VirtualTimeLoop:
    running = asyncio.get_running_loop()
    assert isinstance(running, VirtualTimeLoop)
    return running


@pytest.mark.cas_virtual
async def test_a_motion_in_sight_is_seen_a_latency_after_it_started() -> None:
    environment, network = world()
    network.receive(1, Observation([started(0.0, 1, 8.0)]), [])
    await asyncio.sleep(L / 2)
    assert environment.within(OWN, 10.0, loop().time()).ids.tolist() == []
    await asyncio.sleep(L)
    assert environment.within(OWN, 10.0, loop().time()).ids.tolist() == [OTHER]
    assert network.applied == 1


@pytest.mark.cas_virtual
async def test_a_hidden_robot_comes_into_sight_where_its_newest_motion_put_it() -> None:
    environment, network = world()
    network.watch([])  # robot OTHER out of sight
    assert network.watched == 0
    await asyncio.sleep(1.0)
    # Heard late and out of order, from a worker this one did not wait for.
    network.receive(1, Observation([started(0.4, 2, 8.0), started(0.2, 1, 6.0)]), [])
    network.receive(1, Observation([started(0.4, 1, 9.0)]), [])  # an older count, same time
    assert environment.within(OWN, 10.0, loop().time()).ids.tolist() == []
    network.watch([OTHER])
    assert network.watched == 1
    assert environment.within(OWN, 10.0, loop().time()).ids.tolist() == [OTHER]
    assert environment.pose_at(OTHER, loop().time()).x == 8.0
    assert network.applied == 0  # kept, never applied in the past


@pytest.mark.cas_virtual
async def test_a_motion_in_sight_heard_after_its_instant_is_an_error() -> None:
    _, network = world()
    await asyncio.sleep(1.0)
    with pytest.raises(SimulationError, match=r"worker 0: the motion robot 2 started at 0\.2 "):
        network.receive(1, Observation([started(0.2, 1, 6.0)]), [])
