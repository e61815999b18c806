"""Swarm: robots opened together, run together, stopped together."""

from __future__ import annotations

import asyncio

import pytest

from cas_async import (
    ConfigurationError,
    Layer,
    LayerError,
    MemoryTransport,
    Message,
    Robot,
    RobotState,
    RobotStateError,
    Swarm,
    UdpTransport,
)
from cas_async.testing import wait_all_tasks_blocked
from tests.stacks import STACK_MESSAGES, Note, Recorder
from tests.taps import Tap


class GreetAtStart(Recorder):
    """Messages every other robot from its very first inner_process."""

    def __init__(self, swarm_size: int) -> None:
        super().__init__()
        self.swarm_size = swarm_size
        self.expected = swarm_size - 1

    async def inner_process(self) -> None:
        await super().inner_process()
        if self.inner_calls == 1:
            for other in range(self.swarm_size):
                if other != self.robot_id:
                    self.send(other, Note(f"hi from {self.robot_id}", []))


def greeting_swarm(transport: MemoryTransport | UdpTransport, size: int = 4) -> Swarm:
    return Swarm(
        Robot(i, [GreetAtStart(size), Layer()], transport=transport, messages=STACK_MESSAGES)
        for i in range(size)
    )


@pytest.mark.parametrize("transport", [MemoryTransport, UdpTransport])
async def test_every_endpoint_is_open_before_any_layer_starts(transport) -> None:
    swarm = greeting_swarm(transport())
    async with swarm:
        await asyncio.wait_for(swarm.run(), 5)
    for robot in swarm:
        assert len(robot.layers[0].external) == 3
        assert robot.state is RobotState.STOPPED
    assert swarm.counters()["sent_external"] == 12


async def test_a_failing_robot_stops_the_swarm_and_run_raises() -> None:
    class Fails(Layer):
        async def handle_msg(self, msg: Message) -> None:
            raise KeyError("bad greeting")

    transport = MemoryTransport()
    robots = [
        Robot(0, [GreetAtStart(2), Layer()], transport=transport, messages=STACK_MESSAGES),
        Robot(1, [Fails(), Layer()], transport=transport, messages=STACK_MESSAGES),
    ]
    robots[0].layers[0].expected = 99  # would wait forever without the failure
    swarm = Swarm(robots)
    with pytest.raises(LayerError, match=r"robot 1, layer 0 \(Fails\) failed: KeyError"):
        async with swarm:
            await asyncio.wait_for(swarm.run(), 5)
    assert [robot.state for robot in swarm] == [RobotState.STOPPED] * 2


async def test_opening_failure_closes_what_was_opened() -> None:
    transport = MemoryTransport()
    taken = Robot(1, [Layer()], transport=transport, messages=STACK_MESSAGES)
    async with taken:
        swarm = Swarm(
            Robot(i, [Layer()], transport=transport, messages=STACK_MESSAGES) for i in (0, 1)
        )
        with pytest.raises(ConfigurationError, match="robot 1 is already attached"):
            async with swarm:
                pass
        assert swarm[0].state is RobotState.STOPPED
        assert list(transport._endpoints) == [1]  # robot 0's endpoint was closed again


def test_duplicate_ids_are_refused() -> None:
    with pytest.raises(ConfigurationError, match="two robots with id 3"):
        Swarm([Robot(3, [Layer()]), Robot(3, [Layer()])])


async def test_run_before_start_is_refused() -> None:
    swarm = Swarm([Robot(1, [Layer()])])
    with pytest.raises(RobotStateError, match="start it with `async with swarm:`"):
        await swarm.run()
    assert len(swarm) == 1
    assert swarm[1].robot_id == 1


class Lingers(Recorder):
    """On cancellation, still tells robot 0 goodbye (a common clean-up pattern)."""

    async def inner_process(self) -> None:
        try:
            await asyncio.Event().wait()
        finally:
            if self.robot_id != 0:
                self.send(0, Note(f"bye from {self.robot_id}", []))


async def test_swarm_stops_every_robot_before_closing_any() -> None:
    transport = MemoryTransport()
    swarm = Swarm(
        Robot(i, [Lingers(), Layer()], transport=transport, messages=STACK_MESSAGES)
        for i in range(3)
    )
    async with swarm:
        await wait_all_tasks_blocked()
    assert [robot.state for robot in swarm] == [RobotState.STOPPED] * 3


async def test_swarm_exit_under_cancellation_still_stops_every_robot() -> None:
    transport = MemoryTransport()
    swarm = Swarm(
        Robot(i, [Recorder(), Layer()], transport=transport, messages=STACK_MESSAGES)
        for i in range(3)
    )
    for robot in swarm:
        robot.layers[0].expected = 99

    async def embed() -> None:
        async with swarm:
            await swarm.run()

    task = asyncio.create_task(embed())
    await wait_all_tasks_blocked()
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert [robot.state for robot in swarm] == [RobotState.STOPPED] * 3
    assert not transport._endpoints


class _Idle(Layer):
    def termination_condition(self) -> bool:
        return False


@pytest.mark.parametrize("inner", [MemoryTransport, UdpTransport])
async def test_robots_hear_of_each_other_only_while_they_run(inner) -> None:
    # Opening n robots used to tell each opened one of every later one (and closing
    # likewise): n squared calls, 47 s to open 11,600 robots. News goes to running robots.
    tap = Tap(inner())
    swarm = Swarm(Robot(i, [_Idle()], transport=tap, messages=STACK_MESSAGES) for i in range(30))
    async with swarm:
        assert all(not news for news in tap.news.values())  # opened, then started: no news
        await swarm.add(Robot(30, [_Idle()], transport=tap, messages=STACK_MESSAGES))
        await swarm.remove(0)
        for robot_id in range(1, 30):
            assert tap.news[robot_id] == [("joined", 30), ("left", 0)]
        assert tap.news[30] == [("left", 0)]
        before = {robot_id: len(news) for robot_id, news in tap.news.items()}
    assert {robot_id: len(news) for robot_id, news in tap.news.items()} == before  # closing
