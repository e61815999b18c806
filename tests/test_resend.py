"""``Layer.resend``: an external message sent again, unchanged, for a layer's own retries.

A resent message keeps its id, so the receiver handles it at most once; a resent
NEGOTIATION that was answered gets the kept reply again, which the asker drops as a
duplicate. Only an external message this very layer sent may be resent.
"""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any, Literal, TypeVar

import pytest

import cas_async
from cas_async import (
    Faults,
    FaultyTransport,
    Layer,
    MemoryTransport,
    Message,
    MsgType,
    Robot,
    RobotStateError,
    RuleViolation,
    Swarm,
    Transport,
    VirtualClock,
)
from cas_async.transport import Codec
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, Recorder
from tests.taps import Tap

T = TypeVar("T")


def robot(robot_id: int, layers: list[Layer], transport: Transport, clock: VirtualClock) -> Robot:
    return Robot(robot_id, layers, transport=transport, clock=clock, messages=STACK_MESSAGES)


def pair(
    transport: Transport,
    clock: VirtualClock,
    *,
    sender_transport: Transport | None = None,
    receiver_transport: Transport | None = None,
) -> tuple[Recorder, Recorder, list[Robot]]:
    """Robot 1 (the sender) and robot 2 (the receiver), one recording layer each.

    Each robot sends through ``transport`` unless given its own (a faulty wrapper of it).
    """
    sender, receiver = Recorder(), Recorder()
    robots = [
        robot(1, [sender], sender_transport or transport, clock),
        robot(2, [receiver], receiver_transport or transport, clock),
    ]
    return sender, receiver, robots


def on_virtual_time(main: Callable[[VirtualClock], Coroutine[Any, Any, T]]) -> T:
    return cas_async.run(main(VirtualClock()), virtual=True)


# -- what the receiver sees -----------------------------------------------------------------


def test_a_message_sent_then_resent_is_handled_once() -> None:
    async def main(clock: VirtualClock) -> tuple[list[Message], dict[str, int], dict[str, int]]:
        sender, receiver, robots = pair(MemoryTransport(), clock)
        async with Swarm(robots):
            note = Note("once", [])
            sender.send(2, note)
            await clock.sleep(1.0)
            sender.resend(2, note)
            await clock.sleep(1.0)
        return receiver.external, robots[1].dropped, robots[0].dropped

    handled, dropped, sender_dropped = on_virtual_time(main)
    assert [m.text for m in handled] == ["once"]  # type: ignore[attr-defined]
    assert dropped == {"duplicate": 1}
    assert sender_dropped == {}


def test_resend_keeps_the_header_and_payload() -> None:
    async def main(clock: VirtualClock) -> tuple[list[bytes], Message]:
        tap = Tap()
        sender, _, robots = pair(tap, clock)
        async with Swarm(robots):
            note = Note("same", [1, 2])
            sender.send(2, note)
            sender.resend(2, note)
            await clock.sleep(1.0)
        return tap.received[2], note

    received, note = on_virtual_time(main)
    assert len(received) == 2
    assert received[0] == received[1]  # the very same datagram, header included
    assert note.msg_id != 0


def test_resend_recovers_a_message_the_network_lost() -> None:
    async def main(clock: VirtualClock) -> tuple[list[str], dict[str, int], dict[str, int]]:
        memory = MemoryTransport()
        lossy = FaultyTransport(memory, Faults(loss=1.0), clock=clock)
        sender, receiver, robots = pair(memory, clock, sender_transport=lossy)
        async with Swarm(robots):
            note = Note("late", [])
            sender.send(2, note)  # lost on the wire
            await clock.sleep(1.0)
            lossy.faults = Faults()
            sender.resend(2, note)
            await clock.sleep(1.0)
        return [m.text for m in receiver.external], robots[1].dropped, lossy.stats  # type: ignore[attr-defined]

    texts, dropped, stats = on_virtual_time(main)
    assert texts == ["late"]
    assert dropped == {}
    assert stats["lost"] == 1


def test_a_resent_answered_negotiation_gets_the_same_reply_again() -> None:
    async def main(
        clock: VirtualClock,
    ) -> tuple[Recorder, Recorder, list[Robot], list[Message], Message]:
        tap = Tap()
        sender, receiver, robots = pair(tap, clock)
        async with Swarm(robots):
            query = Query(21, msg_type=MsgType.NEGOTIATION)
            sender.send(2, query)
            await clock.sleep(1.0)
            sender.resend(2, query)
            await clock.sleep(1.0)
            codec = Codec.for_stack(1, STACK_MESSAGES)
            replies = [codec.decode(data) for data in tap.received[1]]
        return sender, receiver, robots, replies, query

    sender, receiver, robots, replies, query = on_virtual_time(main)
    # The receiver handled the question once, and answered the repetition from its memory.
    assert [m.msg_id for m in receiver.external] == [query.msg_id]
    assert robots[1].dropped == {"duplicate": 1}
    assert robots[1].counters()["replies_resent"] == 1
    assert robots[1].counters()["sent_external"] == 1  # the kept reply is not a new message
    # The asker got the same reply twice and handled it once.
    assert len(replies) == 2
    first, second = replies
    assert isinstance(first, Answer)
    assert first.value == 42
    assert (second.msg_id, second.corr_id) == (first.msg_id, first.corr_id)
    assert first.corr_id == query.msg_id
    assert [m.msg_id for m in sender.external] == [first.msg_id]
    assert robots[0].dropped == {"duplicate": 1}


def _negotiation_resent_after_a_loss(
    lossy_side: Literal["sender", "receiver"], value: int
) -> tuple[list[Message], int, list[Robot]]:
    """Sends a negotiation that ``lossy_side``'s transport loses, then resends it once.

    A lossy sender loses the first request; a lossy receiver loses the first reply.

    Returns the sender's external messages, how many the receiver handled, and the robots.
    """

    async def main(clock: VirtualClock) -> tuple[list[Message], int, list[Robot]]:
        memory = MemoryTransport()
        lossy = FaultyTransport(memory, Faults(loss=1.0), clock=clock)
        sender, receiver, robots = pair(
            memory,
            clock,
            sender_transport=lossy if lossy_side == "sender" else None,
            receiver_transport=lossy if lossy_side == "receiver" else None,
        )
        async with Swarm(robots):
            query = Query(value, msg_type=MsgType.NEGOTIATION)
            sender.send(2, query)
            await clock.sleep(1.0)
            lossy.faults = Faults()
            sender.resend(2, query)
            await clock.sleep(1.0)
        return sender.external, len(receiver.external), robots

    return on_virtual_time(main)


def test_a_resent_negotiation_whose_reply_was_lost_gets_the_kept_reply() -> None:
    """The retry a layer makes from a timer: the receiver answers without handling it again."""
    answers, handled, robots = _negotiation_resent_after_a_loss("receiver", 4)
    assert [(type(m), m.value) for m in answers] == [(Answer, 8)]  # type: ignore[attr-defined]
    assert handled == 1
    assert robots[1].counters()["replies_resent"] == 1
    assert robots[1].dropped == {"duplicate": 1}
    assert robots[0].dropped == {}


def test_a_resent_unanswered_negotiation_is_answered_once() -> None:
    """The first copy was lost: the receiver handles the resent one and answers it."""
    answers, handled, robots = _negotiation_resent_after_a_loss("sender", 5)
    assert handled == 1
    assert [(type(m), m.value) for m in answers] == [(Answer, 10)]  # type: ignore[attr-defined]
    assert robots[1].counters()["replies_resent"] == 0
    assert robots[1].dropped == robots[0].dropped == {}


# -- counters -------------------------------------------------------------------------------


def test_resend_counts_as_an_external_message_sent() -> None:
    async def main(clock: VirtualClock) -> tuple[dict[str, int], dict[str, dict[str, int]]]:
        sender, _, robots = pair(MemoryTransport(), clock)
        async with Swarm(robots):
            note = Note("x", [])
            sender.send(2, note)
            sender.resend(2, note)
            sender.resend(2, note)
            await clock.sleep(1.0)
        return robots[0].counters(), robots[0].message_counts()

    counters, by_class = on_virtual_time(main)
    assert counters["sent_external"] == 3
    assert by_class["external"] == {"Note": 3}


def test_a_resend_to_an_unknown_robot_is_dropped_and_counted() -> None:
    async def main(clock: VirtualClock) -> dict[str, int]:
        sender, _, robots = pair(MemoryTransport(), clock)
        async with Swarm(robots):
            note = Note("x", [])
            sender.send(2, note)
            sender.resend(9, note)
        return robots[0].counters()

    counts = on_virtual_time(main)
    assert (counts["sent_external"], counts["dropped.unknown_robot"]) == (1, 1)


# -- what may be resent ---------------------------------------------------------------------


def two_layers() -> list[Layer]:
    return [Recorder(), Recorder()]


def test_a_message_never_sent_cannot_be_resent() -> None:
    async def main(clock: VirtualClock) -> dict[str, int]:
        sender, _, robots = pair(MemoryTransport(), clock)
        async with Swarm(robots):
            with pytest.raises(RuleViolation, match="resend\\(\\) needs a message this layer sent"):
                sender.resend(2, Note("never sent", []))
        return robots[0].counters()

    assert on_virtual_time(main)["sent_external"] == 0


def test_a_message_received_from_another_robot_cannot_be_resent() -> None:
    async def main(clock: VirtualClock) -> int:
        sender, receiver, robots = pair(MemoryTransport(), clock)
        async with Swarm(robots):
            sender.send(2, Note("to 2", []))
            await clock.sleep(1.0)
            [received] = receiver.external
            with pytest.raises(RuleViolation, match="needs a message this layer sent"):
                receiver.resend(1, received)
            with pytest.raises(RuleViolation, match="needs a message this layer sent"):
                receiver.resend(3, received)  # not even to a third robot
        return len(sender.external)

    assert on_virtual_time(main) == 0


@pytest.mark.parametrize("direction", ["down", "up", "received"])
def test_an_internal_message_cannot_be_resent(direction: str) -> None:
    async def main(clock: VirtualClock) -> tuple[int, int]:
        top, bottom = layers = two_layers()
        async with robot(1, layers, MemoryTransport(), clock):
            note = Note("inside", [])
            if direction == "down":
                top.send_down(note)
                layer: Layer = top
            elif direction == "up":
                bottom.send_up(note)
                layer = bottom
            else:
                top.send_down(note)
                await clock.sleep(1.0)
                [note] = bottom.internal  # type: ignore[attr-defined]
                layer = bottom
            assert note.msg_id != 0
            with pytest.raises(RuleViolation, match="needs a message this layer sent"):
                layer.resend(1, note)
        return top.counters.sent_external, bottom.counters.sent_external

    assert on_virtual_time(main) == (0, 0)


def test_a_message_another_layer_of_the_robot_sent_cannot_be_resent() -> None:
    async def main(clock: VirtualClock) -> tuple[int, int]:
        memory = MemoryTransport()
        mine, theirs = two_layers(), two_layers()
        robots = [robot(1, mine, memory, clock), robot(2, theirs, memory, clock)]
        top, bottom = mine
        async with Swarm(robots):
            note = Note("from the top", [])
            top.send(2, note)
            with pytest.raises(RuleViolation, match="needs a message this layer sent"):
                bottom.resend(2, note)
            await clock.sleep(1.0)
        return len(theirs[0].external), len(theirs[1].external)  # type: ignore[attr-defined]

    assert on_virtual_time(main) == (1, 0)


def test_a_reply_this_layer_sent_may_be_resent() -> None:
    """A reply is an external message too: resent, it is the same reply, dropped as one."""

    async def main(clock: VirtualClock) -> tuple[int, dict[str, int]]:
        sender, receiver, robots = pair(MemoryTransport(), clock)
        async with Swarm(robots):
            sender.send(2, Query(1, msg_type=MsgType.NEGOTIATION))
            await clock.sleep(1.0)
            [answer] = sender.external
            [question] = receiver.external
            kept = Answer(2, 0)
            receiver.reply(question, kept)  # a second, explicit reply object
            await clock.sleep(1.0)
            receiver.resend(1, kept)
            await clock.sleep(1.0)
            assert answer.msg_id != kept.msg_id
        return len(sender.external), robots[0].dropped

    handled, dropped = on_virtual_time(main)
    assert handled == 2  # the automatic answer and the explicit one, each once
    assert dropped == {"duplicate": 1}


def test_a_stopped_robot_cannot_resend() -> None:
    async def main(clock: VirtualClock) -> None:
        sender, _, robots = pair(MemoryTransport(), clock)
        note = Note("x", [])
        async with Swarm(robots):
            sender.send(2, note)
        with pytest.raises(RobotStateError, match="cannot send: robot 1 is"):
            sender.resend(2, note)

    on_virtual_time(main)
