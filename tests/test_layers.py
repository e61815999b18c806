"""Inside one robot: forwarding, automatic NEGOTIATION replies, rules, the layer loop."""

from __future__ import annotations

import asyncio

import pytest

import cas_async
from cas_async import (
    Layer,
    MemoryTransport,
    Message,
    MsgType,
    RequestTimeout,
    Robot,
    RuleViolation,
    VirtualClock,
)
from cas_async.testing import wait_all_tasks_blocked
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, Recorder, recorders


class Sender(Recorder):
    """A recorder that sends what the test queues, from its own task."""

    def __init__(self) -> None:
        super().__init__()
        self.outbox: list[tuple[str, int, Message]] = []

    async def inner_process(self) -> None:
        await super().inner_process()
        for how, level, msg in self.outbox:
            if how == "up":
                self.send_up(msg)
            elif how == "down":
                self.send_down(msg)
            else:
                self.send_to_layer(level, msg)
        self.outbox.clear()


async def test_forwarding_across_five_layers_both_ways(start_robot) -> None:
    stack = recorders(5)
    robot = await start_robot(1, stack)
    stack[0].send_to_layer(4, Note("down", []))
    stack[4].send_to_layer(0, Note("up", []))
    await wait_all_tasks_blocked()
    (down,) = stack[4].internal
    (up,) = stack[0].internal
    assert (down.text, down.src_layer, down.dst_layer) == ("down", 0, 4)
    assert (up.text, up.src_layer, up.dst_layer) == ("up", 4, 0)
    # Each of the three intermediate layers forwarded both, without seeing them.
    assert [layer.counters.forwarded for layer in stack] == [0, 2, 2, 2, 0]
    assert all(not layer.internal for layer in stack[1:4])
    assert robot.counters()["forwarded"] == 6


async def test_neighbour_sends_reach_store_intra_msg(start_robot) -> None:
    stack = recorders(3)
    await start_robot(1, stack)
    stack[1].send_up(Note("to top", []))
    stack[1].send_down(Note("to bottom", []))
    await wait_all_tasks_blocked()
    assert [m.text for m in stack[0].internal] == ["to top"]
    assert [m.text for m in stack[2].internal] == ["to bottom"]
    assert stack[0].internal[0].msg_type == MsgType.ACCEPT


async def test_header_is_filled_by_the_runtime(start_robot) -> None:
    stack = recorders(2)
    await start_robot(7, stack)
    first, second = Note("a", []), Note("b", [])
    stack[0].send_down(first)
    stack[0].send_down(second)
    assert (first.robot_id, first.src_layer, first.dst_layer, first.corr_id) == (7, 0, 1, 0)
    assert second.msg_id > first.msg_id > 0


async def test_negotiation_across_non_neighbours_is_answered_automatically(start_robot) -> None:
    stack = recorders(4)
    await start_robot(1, stack)
    stack[0].send_to_layer(3, Query(21, msg_type=MsgType.NEGOTIATION))
    await wait_all_tasks_blocked()
    (question,) = stack[3].negotiations
    assert not stack[3].internal  # a NEGOTIATION goes to get_intra_msg_reply only
    (reply,) = stack[0].internal
    assert isinstance(reply, Answer)
    assert (reply.value, reply.by_level) == (42, 3)
    assert (reply.src_layer, reply.dst_layer, reply.corr_id) == (3, 0, question.msg_id)


@pytest.mark.parametrize(
    ("asker", "target", "value", "expected_type"),
    [
        pytest.param(0, 4, 5, MsgType.ACCEPT, id="top-asks-bottom"),
        pytest.param(4, 0, 6, MsgType.ACCEPT, id="bottom-asks-top"),
        pytest.param(2, 3, 7, MsgType.ACCEPT, id="neighbour"),
        pytest.param(1, 4, -1, MsgType.DENY, id="denied"),
    ],
)
async def test_request_layer_returns_the_reply(
    start_robot, asker, target, value, expected_type
) -> None:
    stack = recorders(5)
    await start_robot(1, stack)
    reply = await stack[asker].request_layer(target, Query(value), timeout=1)
    assert isinstance(reply, Answer)
    assert (reply.value, reply.by_level, reply.msg_type) == (value * 2, target, expected_type)
    assert not stack[asker].internal  # the awaited reply does not reach the hooks too


async def test_request_down_and_up(start_robot) -> None:
    stack = recorders(3)
    await start_robot(1, stack)
    assert (await stack[1].request_down(Query(1))).by_level == 2
    assert (await stack[1].request_up(Query(1))).by_level == 0


async def test_request_works_while_the_asking_layer_is_busy_in_a_hook(start_robot) -> None:
    class Asker(Recorder):
        async def store_intra_msg(self, msg: Message) -> None:
            # Blocking this layer's loop must not block its own reply.
            self.answer = await self.request_layer(2, Query(4), timeout=1)
            await super().store_intra_msg(msg)

    stack = [Asker(), Recorder(), Recorder()]
    await start_robot(1, stack)
    stack[1].send_up(Note("go", []))
    await wait_all_tasks_blocked()
    assert stack[0].answer.value == 8


async def test_request_without_reply_times_out(start_robot) -> None:
    class Silent(Recorder):
        async def get_intra_msg_reply(self, msg: Message) -> Message | None:
            return None

    stack = [Recorder(), Silent()]
    await start_robot(1, stack)
    with pytest.raises(
        RequestTimeout, match=r"robot 1 Recorder\(L0\): no reply from layer 1 to Query"
    ):
        await stack[0].request_down(Query(1), timeout=0.05)


@pytest.mark.parametrize(
    ("sender", "how", "level", "reason"),
    [
        pytest.param(0, "up", 0, "no_layer_above", id="send_up-from-top"),
        pytest.param(2, "down", 0, "no_layer_below", id="send_down-from-bottom"),
        pytest.param(1, "to", 7, "no_such_layer", id="beyond-the-stack"),
        pytest.param(1, "to", -1, "no_such_layer", id="negative-level"),
        pytest.param(1, "to", 1, "to_self", id="to-its-own-level"),
    ],
)
@pytest.mark.cas_allow_drops("no_layer_above", "no_layer_below", "no_such_layer", "to_self")
async def test_internal_rule_violations_are_dropped_and_counted(
    start_robot, caplog, sender, how, level, reason
) -> None:
    stack = [Sender(), Sender(), Sender()]
    robot = await start_robot(1, stack)
    stack[sender].outbox.append((how, level, Note("bad", [])))
    stack[(sender + 1) % 3].send_to_layer(
        sender, Note("wake", [])
    )  # runs the sender's inner_process
    await wait_all_tasks_blocked()
    assert robot.dropped == {reason: 1}
    assert robot.counters()[f"dropped.{reason}"] == 1
    assert all(m.text != "bad" for layer in stack for m in layer.internal)
    assert reason in caplog.text
    assert "Sender(L" in caplog.text


@pytest.mark.cas_allow_drops("to_own_robot")
async def test_external_send_to_own_robot_is_a_violation(start_robot, cas_memory) -> None:
    stack = recorders(2)
    robot = await start_robot(1, stack, transport=cas_memory)
    stack[0].send(1, Note("me", []))
    await wait_all_tasks_blocked()
    assert robot.dropped == {"to_own_robot": 1}
    assert not stack[0].external


async def test_inner_process_runs_at_start_and_after_each_batch(start_robot) -> None:
    stack = recorders(2)
    await start_robot(1, stack)
    await wait_all_tasks_blocked()
    assert stack[1].inner_calls == 1
    for i in range(5):  # one burst: delivered as one batch
        stack[0].send_down(Note(str(i), []))
    await wait_all_tasks_blocked()
    assert stack[1].inner_calls == 2
    assert [m.text for m in stack[1].internal] == ["0", "1", "2", "3", "4"]
    stack[0].send_down(Note("again", []))
    await wait_all_tasks_blocked()
    assert stack[1].inner_calls == 3


async def test_forwarding_does_not_wake_the_intermediate_layer(start_robot) -> None:
    stack = recorders(3)
    await start_robot(1, stack)
    await wait_all_tasks_blocked()
    stack[0].send_to_layer(2, Note("through", []))
    await wait_all_tasks_blocked()
    assert stack[1].inner_calls == 1  # only the start-up call
    assert stack[2].inner_calls == 2


async def test_layers_that_define_no_condition_abstain(start_robot) -> None:
    class Done(Layer):
        def termination_condition(self) -> bool:
            return True

    robot = await start_robot(1, [Done(), Layer(), Layer()])
    await robot.run()  # returns: the only layer with a say is done


async def test_run_returns_when_every_condition_holds(start_robot) -> None:
    stack = recorders(3)
    for layer in stack:
        layer.expected = 1
    robot = await start_robot(1, stack)
    stack[0].send_down(Note("x", []))
    stack[1].send_up(Note("y", []))
    stack[1].send_down(Note("z", []))
    await robot.run()
    assert [len(layer.internal) for layer in stack] == [1, 1, 1]


async def test_reusing_a_message_object_delivers_each_send_to_its_own_layer(start_robot) -> None:
    stack = recorders(3)
    robot = await start_robot(1, stack)
    note = Note("twice", [])
    stack[1].send_up(note)
    stack[1].send_down(note)  # still travelling upwards: a copy goes down
    await wait_all_tasks_blocked()
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


@pytest.mark.cas_allow_drops("to_own_robot", "no_such_layer")
async def test_rule_breaking_requests_raise_rule_violation(start_robot) -> None:
    stack = recorders(2)
    robot = await start_robot(1, stack, transport=MemoryTransport())
    with pytest.raises(RuleViolation, match="request\\(\\) to its own robot 1"):
        await stack[0].request(1, Query(1))
    with pytest.raises(RuleViolation, match="no layer 5 to ask"):
        await stack[0].request_layer(5, Query(1))
    assert robot.dropped == {"to_own_robot": 1, "no_such_layer": 1}
