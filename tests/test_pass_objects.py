"""MemoryTransport(pass_objects=True): messages travel as objects, owned by one robot at a time."""

from __future__ import annotations

import pytest

from cas_async import ConfigurationError, MemoryTransport, Message, MsgType, Robot, message
from cas_async.testing import wait_all_tasks_blocked
from tests.stacks import STACK_MESSAGES, Note, Query, Recorder, recorders
from tests.taps import Tap


@pytest.fixture
def objects() -> MemoryTransport:
    return MemoryTransport(pass_objects=True)


async def test_the_receiver_gets_the_object_sent_with_its_header(start_robot, objects) -> None:
    a, b = recorders(2), recorders(2)
    await start_robot(1, a, transport=objects)
    await start_robot(2, b, transport=objects)
    note = Note("hello", [1])
    a[1].send(2, note)
    await wait_all_tasks_blocked()
    (got,) = b[1].external
    assert got is note  # no encoding: the very object
    assert (got.robot_id, got.src_layer, got.dst_layer, got.msg_id > 0) == (1, 1, 1, True)


async def test_sending_an_object_again_sends_a_copy(start_robot, objects) -> None:
    a, b, c = recorders(1), recorders(1), recorders(1)
    await start_robot(1, a, transport=objects)
    await start_robot(2, b, transport=objects)
    await start_robot(3, c, transport=objects)
    note = Note("twice", [])
    a[0].send(2, note)
    a[0].send(3, note)  # before robot 2 has even received the first
    await wait_all_tasks_blocked()
    (first,), (second,) = b[0].external, c[0].external
    assert first is note
    assert second is not note
    assert second.text == "twice"
    assert first.msg_id != second.msg_id  # the first kept its own header


async def test_each_receiver_of_a_broadcast_gets_its_own_message(start_robot, objects) -> None:
    stacks = [recorders(1) for _ in range(4)]
    for robot_id, stack in enumerate(stacks, start=1):
        await start_robot(robot_id, stack, transport=objects)
    note = Note("all", [7])
    stacks[0][0].broadcast(note)
    await wait_all_tasks_blocked()
    received = [stack[0].external[0] for stack in stacks[1:]]
    assert len({id(msg) for msg in received}) == 3
    assert {(msg.text, msg.msg_id) for msg in received} == {("all", received[0].msg_id)}
    stacks[0][0].broadcast(note)  # again: the receiver holding it keeps its header
    await wait_all_tasks_blocked()
    assert {msg.msg_id for msg in received} == {received[0].msg_id}
    assert len({stack[0].external[1].msg_id for stack in stacks[1:]} | {note.msg_id}) == 2


@pytest.mark.cas_allow_drops("duplicate")
async def test_a_request_is_answered_and_a_repeated_one_gets_the_kept_reply(
    start_robot, objects
) -> None:
    a, b = recorders(1), recorders(1)
    robot_a = await start_robot(1, a, transport=objects)
    robot_b = await start_robot(2, b, transport=objects)
    assert (await a[0].request(2, Query(4), timeout=5)).value == 8
    query = Query(5)
    query.msg_type = MsgType.NEGOTIATION
    a[0].send(2, query)  # answered into handle_msg
    await wait_all_tasks_blocked()
    a[0].resend(2, query)  # as after a lost reply: the same id again
    await wait_all_tasks_blocked()
    assert robot_b.counters()["replies_resent"] == 1
    assert robot_b.dropped == {"duplicate": 1}
    assert [m.value for m in a[0].external] == [10]  # the kept reply again is a duplicate
    assert robot_a.dropped == {"duplicate": 1}


async def test_robots_of_different_stacks_cannot_share_the_transport(start_robot, objects) -> None:
    await start_robot(1, recorders(2), transport=objects)
    with pytest.raises(ConfigurationError, match=r"robot 2: its stack .* differs from robot 1's"):
        await start_robot(2, recorders(3), transport=objects)


@pytest.mark.cas_allow_drops("decode.malformed", "decode.unknown_type")
async def test_what_is_not_a_message_of_the_stack_is_dropped_and_counted(
    start_robot, objects
) -> None:
    @message
    class Stranger(Message):
        n: int

    a, b = recorders(1), recorders(1)
    tap = Tap(objects)
    await start_robot(1, a, transport=tap)
    robot_b = await start_robot(2, b, transport=tap)
    tap.deliver(2, b"\x93\x01\x02\x03", 1)  # bytes fed in by hand
    a[0].send(2, Stranger(1))  # over UDP its encoding would fail at the sender
    await wait_all_tasks_blocked()
    assert robot_b.dropped == {"decode.malformed": 1, "decode.unknown_type": 1}
    assert not b[0].external


async def test_an_object_reaching_a_stopped_robot_is_counted(objects) -> None:
    tap = Tap(objects)
    async with Robot(2, [Recorder()], transport=tap, messages=STACK_MESSAGES) as receiver:
        pass  # started and stopped: what arrives now finds it not running
    tap.deliver(2, Note("late", []), 1)  # type: ignore[arg-type]  # an object, as robots pass
    assert receiver.dropped == {"not_running": 1}
