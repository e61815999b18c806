"""A robot's lifecycle: start, run, stop, failures, and what is left behind."""

from __future__ import annotations

import asyncio
import gc

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
)
from cas_async.testing import wait_all_tasks_blocked
from tests.stacks import STACK_MESSAGES, Note, Query, Recorder, recorders


class Boom(Recorder):
    """Raises when it receives a message."""

    async def store_intra_msg(self, msg: Message) -> None:
        raise ValueError(f"cannot handle {msg.text}")  # type: ignore[attr-defined]


class BoomAtStart(Layer):
    async def inner_process(self) -> None:
        raise RuntimeError("broken at start")


def _other_tasks() -> set[asyncio.Task[object]]:
    return {t for t in asyncio.all_tasks() if t is not asyncio.current_task()}


async def test_exception_in_a_layer_names_robot_and_layer_and_stops_the_robot() -> None:
    stack = [Recorder(), Boom(), Recorder()]
    for layer in stack:
        layer.expected = 1
    robot = Robot(4, stack, messages=STACK_MESSAGES)
    with pytest.raises(LayerError) as caught:
        async with robot:
            stack[0].send_down(Note("poison", []))
            await asyncio.wait_for(robot.run(), 5)
    error = caught.value
    assert str(error) == "robot 4, layer 1 (Boom) failed: ValueError: cannot handle poison"
    assert (error.robot_id, error.level, error.layer_name) == (4, 1, "Boom")
    assert isinstance(error.__cause__, ValueError)
    assert robot.state is RobotState.STOPPED
    assert not _other_tasks()  # every layer task was cancelled and awaited


async def test_failure_surfaces_on_leaving_the_block_when_run_was_not_awaited() -> None:
    robot = Robot(5, [BoomAtStart(), Layer()], messages=STACK_MESSAGES)
    with pytest.raises(LayerError, match=r"robot 5, layer 0 \(BoomAtStart\) failed"):
        async with robot:
            await wait_all_tasks_blocked()
    assert not _other_tasks()


async def test_failure_after_run_returned_still_surfaces() -> None:
    stack = [Recorder(), Boom()]  # expected == 0: every condition holds at once
    robot = Robot(4, stack, messages=STACK_MESSAGES)
    with pytest.raises(LayerError, match=r"layer 1 \(Boom\)"):
        async with robot:
            await robot.run()
            stack[0].send_down(Note("after", []))
            await wait_all_tasks_blocked()


async def test_failure_does_not_cancel_the_embedding_task() -> None:
    robot = Robot(6, [BoomAtStart()], messages=STACK_MESSAGES)
    ticks = 0
    with pytest.raises(LayerError):
        async with robot:
            for _ in range(10):  # the embedding code keeps running after the failure
                ticks += 1
                await asyncio.sleep(0)
    assert ticks == 10


async def test_clean_shutdown_leaves_no_pending_tasks(recwarn) -> None:
    transport = MemoryTransport()
    robots = [Robot(i, recorders(3), transport=transport, messages=STACK_MESSAGES) for i in (1, 2)]
    async with robots[0], robots[1]:
        robots[0].layers[0].send(2, Note("hello", []))
        await wait_all_tasks_blocked()
        assert len(_other_tasks()) == 2 + 2 * 3  # a supervisor and three layer tasks each
    assert not _other_tasks()
    assert [r.state for r in robots] == [RobotState.STOPPED] * 2
    gc.collect()
    assert not [w for w in recwarn if "pending" in str(w.message)]


async def test_stop_from_a_layer_ends_run() -> None:
    class Quitter(Layer):
        async def inner_process(self) -> None:
            self.robot.stop()

    robot = Robot(1, [Quitter(), Layer()], messages=STACK_MESSAGES)
    await asyncio.wait_for(robot.run(), 5)  # run() outside `async with` starts and stops
    assert robot.state is RobotState.STOPPED


async def test_a_robot_runs_once() -> None:
    robot = Robot(1, [Layer()], messages=STACK_MESSAGES)
    async with robot:
        with pytest.raises(RobotStateError, match="robot 1 is running; a Robot runs once"):
            await robot.__aenter__()
    with pytest.raises(RobotStateError, match="robot 1 is stopped; a Robot runs once"):
        async with robot:
            pass
    with pytest.raises(RobotStateError, match="a Robot runs once"):
        await robot.run()


async def test_sending_after_stop_is_refused() -> None:
    stack = recorders(2)
    async with Robot(1, stack, messages=STACK_MESSAGES):
        pass
    with pytest.raises(RobotStateError, match="Recorder cannot send: robot 1 is stopped"):
        stack[0].send_down(Note("late", []))


async def test_layer_used_before_its_robot_exists() -> None:
    layer = Recorder()
    with pytest.raises(RobotStateError, match="Recorder is not part of a robot yet"):
        _ = layer.level
    with pytest.raises(RobotStateError, match="not part of a robot"):
        layer.send_down(Note("x", []))


async def test_stop_before_start_is_refused() -> None:
    with pytest.raises(RobotStateError, match="never started"):
        Robot(1, [Layer()]).stop()


@pytest.mark.parametrize(
    ("build", "match"),
    [
        pytest.param(lambda: Robot(1, []), "needs at least one layer", id="no-layers"),
        pytest.param(lambda: Robot("1", [Layer()]), "robot_id must be an int", id="id-not-int"),  # type: ignore[arg-type]
        pytest.param(
            lambda: Robot(1, [Layer, Layer()]),
            "layer 0 is .* not a Layer instance",
            id="class-not-instance",
        ),  # type: ignore[list-item]
    ],
)
def test_invalid_robots_are_refused(build, match) -> None:
    with pytest.raises(ConfigurationError, match=match):
        build()


def test_a_layer_belongs_to_one_robot() -> None:
    shared = Layer()
    Robot(1, [shared])
    with pytest.raises(ConfigurationError, match="already belongs to robot 1"):
        Robot(2, [shared])


async def test_send_without_transport_says_so(start_robot) -> None:
    stack = recorders(1)
    await start_robot(1, stack)
    with pytest.raises(ConfigurationError, match="robot 1 has no transport"):
        stack[0].send(2, Note("x", []))
    with pytest.raises(ConfigurationError, match="robot 1 has no transport"):
        await stack[0].request(2, Note("x", []))
    assert not stack[0].knows(2)


async def test_cancelling_the_embedding_task_still_shuts_down() -> None:
    stack = recorders(2)
    stack[0].expected = 1  # never satisfied: run() waits until cancelled
    robot = Robot(1, stack, messages=STACK_MESSAGES)

    async def embed() -> None:
        async with robot:
            await robot.run()

    task = asyncio.create_task(embed())
    await wait_all_tasks_blocked()
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert robot.state is RobotState.STOPPED
    assert not _other_tasks()


async def test_a_request_pending_at_stop_fails_instead_of_hanging() -> None:
    class Silent(Recorder):
        async def get_intra_msg_reply(self, msg: Message) -> Message | None:
            return None

    stack = [Recorder(), Silent()]
    async with Robot(1, stack, messages=STACK_MESSAGES):
        asking = asyncio.create_task(stack[0].request_down(Query(1), timeout=60))
        await wait_all_tasks_blocked()
    with pytest.raises(RobotStateError, match="stopped while waiting for the reply from layer 1"):
        await asyncio.wait_for(asking, 5)


def test_impossible_limits_are_refused_at_construction() -> None:
    with pytest.raises(ConfigurationError, match="max_datagram_size must be at least 64"):
        Robot(1, [Layer()], max_datagram_size=32)
    with pytest.raises(ConfigurationError, match="queue_limit at least 1"):
        Robot(1, [Layer()], queue_limit=0)


async def test_broadcast_without_a_transport_says_so(start_robot) -> None:
    stack = recorders(1)
    await start_robot(1, stack)
    with pytest.raises(ConfigurationError, match="robot 1 has no transport"):
        stack[0].broadcast(Note("anyone?", []))


def test_log_and_counters_before_joining_a_robot() -> None:
    layer = Recorder()
    with pytest.raises(RobotStateError, match="not part of a robot yet"):
        _ = layer.log
    with pytest.raises(RobotStateError, match="not part of a robot yet"):
        _ = layer.counters
