"""Regression tests for problems a review found: each would fail on the code before it."""

from __future__ import annotations

import asyncio

import msgpack
import pytest

import cas_async
from cas_async import (
    ConfigurationError,
    EncodeError,
    Layer,
    LayerError,
    MemoryTransport,
    Message,
    Robot,
    RobotState,
    RobotStateError,
    RuleViolation,
    Swarm,
    VirtualClock,
    message,
)
from cas_async.transport import Codec
from tests.conftest import settle
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, Recorder, recorders
from tests.taps import Tap


async def test_a_layer_whose_await_is_cancelled_from_outside_fails_the_robot() -> None:
    driver: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    class Waits(Layer):
        async def inner_process(self) -> None:
            await driver  # e.g. a hardware driver's future, cancelled by someone else

    robot = Robot(1, [Waits(), Layer()], messages=STACK_MESSAGES)
    with pytest.raises(LayerError, match=r"robot 1, layer 0 \(Waits\) failed: CancelledError"):
        async with robot:
            await settle()
            driver.cancel()
            await asyncio.wait_for(robot.run(), 5)
    assert robot.state is RobotState.STOPPED


async def test_another_robot_cannot_answer_an_internal_request(start_robot) -> None:
    class Silent(Recorder):
        async def get_intra_msg_reply(self, msg: Message) -> Message | None:
            self.negotiations.append(msg)
            return None

    stack = [Recorder(), Silent()]
    network = Tap()
    robot = await start_robot(1, stack, transport=network)
    await start_robot(2, recorders(2), transport=network)
    asking = asyncio.create_task(stack[0].request_down(Query(1), timeout=5))
    await settle()
    (question,) = stack[1].negotiations
    forged = Answer(666, 0)  # robot 2 guesses the id of robot 1's internal request
    forged.msg_id, forged.robot_id, forged.corr_id = 7, 2, question.msg_id
    network.deliver(1, Codec.for_stack(2, STACK_MESSAGES).encode(forged))
    await settle()
    assert not asking.done()
    assert robot.dropped == {"reply_from_wrong_place": 1}
    asking.cancel()
    with pytest.raises(asyncio.CancelledError):
        await asking


async def test_reusing_a_message_object_delivers_each_send_to_its_own_layer(start_robot) -> None:
    stack = recorders(3)
    robot = await start_robot(1, stack)
    note = Note("twice", [])
    stack[1].send_up(note)
    stack[1].send_down(note)  # still travelling upwards: a copy goes down
    await settle()
    assert [m.text for m in stack[0].internal] == ["twice"]
    assert [m.text for m in stack[2].internal] == ["twice"]
    assert robot.counters()["forwarded"] == 0


async def test_answering_with_the_request_object_itself(start_robot) -> None:
    transport = MemoryTransport()

    class Echo(Recorder):
        async def get_intra_msg_reply(self, msg: Message) -> Message | None:
            msg.value *= 10  # type: ignore[attr-defined]
            return msg

        async def handle_msg(self, msg: Message) -> None:
            msg.value += 1  # type: ignore[attr-defined]
            self.reply(msg, msg)

    mine, theirs = [Recorder(), Echo()], [Echo(), Recorder()]
    await start_robot(1, mine, transport=transport)
    await start_robot(2, theirs, transport=transport)
    internal = await mine[0].request_down(Query(4), timeout=1)
    assert (type(internal), internal.value) == (Query, 40)
    external = await mine[0].request(2, Query(4), timeout=1)
    assert (external.value, external.robot_id) == (5, 2)
    assert not mine[0].internal
    assert not mine[0].external


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
        await settle()
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
    await settle()
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert [robot.state for robot in swarm] == [RobotState.STOPPED] * 3
    assert not transport._endpoints


async def test_a_request_pending_at_stop_fails_instead_of_hanging() -> None:
    class Silent(Recorder):
        async def get_intra_msg_reply(self, msg: Message) -> Message | None:
            return None

    stack = [Recorder(), Silent()]
    async with Robot(1, stack, messages=STACK_MESSAGES):
        asking = asyncio.create_task(stack[0].request_down(Query(1), timeout=60))
        await settle()
    with pytest.raises(RobotStateError, match="stopped while waiting for the reply from layer 1"):
        await asyncio.wait_for(asking, 5)


def test_forwarding_does_not_wait_for_a_busy_intermediate_layer() -> None:
    class Busy(Layer):
        async def inner_process(self) -> None:
            await self.clock.sleep(100)  # e.g. a Task layer waiting for a long motion

    async def main() -> float:
        clock = VirtualClock()
        stack = [Recorder(), Busy(), Recorder()]
        async with Robot(1, stack, clock=clock, messages=STACK_MESSAGES):
            await asyncio.sleep(0)
            reply = await stack[0].request_layer(2, Query(3), timeout=1)
            assert reply.value == 6
            return clock.now()

    assert cas_async.run(main(), virtual=True) < 1.0


def test_a_clock_refuses_a_second_event_loop() -> None:
    clock = VirtualClock()

    async def use() -> None:
        async with Robot(1, [Layer()], clock=clock, messages=STACK_MESSAGES):
            pass

    cas_async.run(use(), virtual=True)
    with pytest.raises(ConfigurationError, match="started on another event loop"):
        cas_async.run(use(), virtual=True)


def test_impossible_limits_are_refused_at_construction() -> None:
    with pytest.raises(ConfigurationError, match="max_datagram_size must be at least 64"):
        Robot(1, [Layer()], max_datagram_size=32)
    with pytest.raises(ConfigurationError, match="queue_limit at least 1"):
        Robot(1, [Layer()], queue_limit=0)


async def test_a_flood_of_foreign_fingerprints_is_explained_a_few_times_only(
    start_robot, caplog
) -> None:
    tap = Tap()
    robot = await start_robot(1, recorders(1), transport=tap)
    for fingerprint in range(1000):
        tap.deliver(1, msgpack.packb([fingerprint, 1, 1, 1, 2, 0, 0, 0]))
    explained = [r for r in caplog.records if "refusing datagrams" in r.getMessage()]
    assert len(explained) == 16
    assert robot.dropped == {"stack_mismatch": 1000}
    assert len(caplog.records) < 30


async def test_late_and_duplicate_replies_are_dropped_not_counted_as_received(start_robot) -> None:
    transport = MemoryTransport()

    class Mute(Recorder):
        async def handle_msg(self, msg: Message) -> None:
            self.external.append(msg)

    asker, answerer = recorders(1), [Mute()]
    robot = await start_robot(1, asker, transport=transport)
    await start_robot(2, answerer, transport=transport)
    asking = asyncio.create_task(asker[0].request(2, Query(1), timeout=5))
    await settle()
    (question,) = answerer[0].external
    answerer[0].reply(question, Answer(2, 0))
    answerer[0].reply(question, Answer(2, 0))  # the same answer twice
    assert (await asking).value == 2
    await settle()
    answerer[0].reply(question, Answer(2, 0))  # and once more, later
    await settle()
    assert robot.dropped == {"duplicate_reply": 2}
    assert asker[0].counters.received_external == 1
    assert not asker[0].external


async def test_rule_breaking_requests_raise_rule_violation(start_robot) -> None:
    stack = recorders(2)
    robot = await start_robot(1, stack, transport=MemoryTransport())
    with pytest.raises(RuleViolation, match="request\\(\\) to its own robot 1"):
        await stack[0].request(1, Query(1))
    with pytest.raises(RuleViolation, match="no layer 5 to ask"):
        await stack[0].request_layer(5, Query(1))
    assert robot.dropped == {"to_own_robot": 1, "no_such_layer": 1}


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


async def test_a_layer_failure_is_noted_on_the_block_s_own_exception() -> None:
    class Boom(Layer):
        async def inner_process(self) -> None:
            raise RuntimeError("boom")

    with pytest.raises(KeyError) as caught:
        async with Robot(1, [Boom()], messages=STACK_MESSAGES):
            await settle()
            raise KeyError("the body's own error")
    assert any("robot 1, layer 0 (Boom) failed" in note for note in caught.value.__notes__)


@message
class WideInt(Message):
    value: int


async def test_integers_beyond_64_bits_get_a_clear_encode_error(start_robot) -> None:
    stack = [Layer()]
    transport = MemoryTransport()
    await start_robot(1, stack, transport=transport, messages=[WideInt])
    await start_robot(2, [Layer()], transport=transport, messages=[WideInt])
    with pytest.raises(EncodeError, match="outside the 64-bit integer range"):
        stack[0].send(2, WideInt(2**70))
