"""Between robots: same-level delivery, requests, broadcast, and what is refused."""

from __future__ import annotations

import asyncio
import socket

import msgpack
import pytest

import cas_async
from cas_async import (
    ConfigurationError,
    EncodeError,
    Layer,
    MemoryTransport,
    Message,
    MsgType,
    RequestTimeout,
    Robot,
    UdpTransport,
    VirtualClock,
    message,
)
from cas_async.testing import wait_all_tasks_blocked
from cas_async.transport import Codec
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, Recorder, recorders
from tests.taps import Tap
from tests.wire import datagram


@pytest.fixture(params=["memory", "pass_objects", "udp"])
def transport(request: pytest.FixtureRequest) -> MemoryTransport | UdpTransport:
    if request.param == "udp":
        return UdpTransport()
    return MemoryTransport(pass_objects=request.param == "pass_objects")


async def wait_for(condition, timeout: float = 5.0) -> None:
    """Polls a condition while real datagrams travel (bounded)."""
    async with asyncio.timeout(timeout):
        while not condition():
            await asyncio.sleep(0.001)


async def test_external_messages_reach_the_same_level(start_robot, transport) -> None:
    a, b = recorders(3), recorders(3)
    await start_robot(1, a, transport=transport)
    await start_robot(2, b, transport=transport)
    a[1].send(2, Note("to level 1", [1, 2]))
    a[2].send(2, Note("to level 2", []))
    await wait_for(lambda: b[1].external and b[2].external)
    (got,) = b[1].external
    assert (got.text, got.hops, got.robot_id, got.src_layer, got.dst_layer) == (
        "to level 1",
        [1, 2],
        1,
        1,
        1,
    )
    assert [m.text for m in b[2].external] == ["to level 2"]
    assert not b[0].external
    assert not b[1].internal


async def test_external_request_and_reply(start_robot, transport) -> None:
    a, b = recorders(2), recorders(2)
    await start_robot(1, a, transport=transport)
    await start_robot(2, b, transport=transport)
    reply = await a[0].request(2, Query(21), timeout=5)
    assert isinstance(reply, Answer)
    assert (reply.value, reply.robot_id, reply.msg_type) == (42, 2, MsgType.ACCEPT)
    assert b[0].external[0].msg_type == MsgType.NEGOTIATION
    assert not a[0].external  # the awaited reply is not also handed to handle_msg


@pytest.mark.cas_allow_drops("late_reply")
async def test_request_to_a_silent_robot_times_out_and_the_late_reply_is_dropped(
    start_robot,
) -> None:
    transport = MemoryTransport()

    class Slow(Recorder):
        async def handle_msg(self, msg: Message) -> None:
            self.pending = msg

    a, b = recorders(1), [Slow()]
    robot_a = await start_robot(1, a, transport=transport)
    await start_robot(2, b, transport=transport)
    with pytest.raises(RequestTimeout, match=r"no reply from robot 2 to Query #\d+ within 0.01 s"):
        await a[0].request(2, Query(1), timeout=0.01)
    b[0].reply(b[0].pending, Answer(2, 0))
    await wait_all_tasks_blocked()
    assert robot_a.dropped == {"late_reply": 1}
    assert not a[0].external


@pytest.mark.cas_allow_drops("reply_from_wrong_place")
async def test_reply_from_another_robot_is_refused(start_robot) -> None:
    transport = MemoryTransport()

    class Mute(Recorder):
        async def handle_msg(self, msg: Message) -> None:
            self.external.append(msg)  # records, never answers by itself

    a, b, c = recorders(1), [Mute()], [Mute()]
    robot_a = await start_robot(1, a, transport=transport)
    await start_robot(2, b, transport=transport)
    await start_robot(3, c, transport=transport)
    asking = asyncio.create_task(a[0].request(2, Query(1), timeout=1))
    await wait_all_tasks_blocked()
    (question,) = b[0].external
    c[0].reply(question, Answer(666, 0))  # robot 3 answers a question put to robot 2
    await wait_all_tasks_blocked()
    assert robot_a.dropped == {"reply_from_wrong_place": 1}
    assert not asking.done()
    b[0].reply(question, Answer(2, 0))
    assert (await asking).value == 2


@pytest.mark.cas_allow_drops("unknown_robot")
async def test_broadcast_reaches_every_other_robot_once(start_robot, transport) -> None:
    stacks = {rid: recorders(2) for rid in (1, 2, 3, 4)}
    for rid, stack in stacks.items():
        await start_robot(rid, stack, transport=transport)
    stacks[1][1].broadcast(Note("all", []))
    stacks[2][0].broadcast(Note("some", []), robots=[3])
    await wait_for(lambda: all(stacks[r][1].external for r in (2, 3, 4)) and stacks[3][0].external)
    assert not stacks[1][1].external
    assert [len(stacks[r][1].external) for r in (2, 3, 4)] == [1, 1, 1]
    assert stacks[1][1].counters.sent_external == 3
    robot = await start_robot(5, recorders(2), transport=transport)
    stacks[1][0].broadcast(Note("x", []), robots=[2, 9])  # 9 is nobody: counted, not raised
    assert stacks[1][0].counters.sent_external == 1
    assert robot.dropped == {}


@pytest.mark.cas_allow_drops("unknown_robot")
async def test_sending_to_an_unknown_robot_is_dropped_and_counted(start_robot, transport) -> None:
    stack = recorders(1)
    robot = await start_robot(1, stack, transport=transport)
    stack[0].send(99, Note("?", []))  # never raised in the sender's hook
    assert robot.dropped == {"unknown_robot": 1}
    assert stack[0].counters.sent_external == 0


@message
class OnlyInOtherStack(Message):
    flag: bool


@pytest.mark.parametrize(
    ("their_layers", "their_messages", "what"),
    [
        pytest.param(3, (*STACK_MESSAGES, OnlyInOtherStack), "message set", id="other-messages"),
        pytest.param(2, STACK_MESSAGES, "2 layers", id="other-layer-count"),
    ],
)
@pytest.mark.cas_allow_drops("stack_mismatch")
async def test_stack_mismatch_is_refused_counted_and_logged_once(
    start_robot, caplog, their_layers, their_messages, what
) -> None:
    transport = MemoryTransport()
    ours = recorders(3)
    theirs = recorders(their_layers)
    robot = await start_robot(1, ours, transport=transport)
    await start_robot(2, theirs, transport=transport, messages=their_messages)
    for _ in range(3):
        theirs[0].send(1, Note("hi", []))
    await wait_all_tasks_blocked()
    assert not ours[0].external
    assert robot.dropped == {"stack_mismatch": 3}
    refusals = [r for r in caplog.records if "refusing datagrams from robot 2" in r.getMessage()]
    assert len(refusals) == 1
    text = refusals[0].getMessage()
    assert what in text
    assert "3 layers" in text
    assert "identical stacks" in text


def _raw_datagram(
    robot: Robot, *fields: object, src: int = 0, dst: int = 0, sender: int = 2
) -> bytes:
    return datagram(robot.fingerprint, Note, fields, src=src, dst=dst, robot_id=sender)


@pytest.mark.cas_allow_drops(
    "decode.malformed",
    "decode.bad_header",
    "decode.unknown_type",
    "decode.wrong_arity",
    "decode.wrong_type",
    "decode.oversize",
    "cross_level",
    "no_such_layer",
    "from_own_id",
    "stack_mismatch",
    "spoofed_sender",
    "unknown_source",
)
async def test_hostile_datagrams_over_real_udp_are_dropped_and_counted(start_robot) -> None:
    transport = UdpTransport()
    stack = recorders(2)
    robot = await start_robot(1, stack, transport=transport)
    prefix = robot.fingerprint.to_bytes(4, "big")
    hostile = {
        "decode.malformed": prefix + b"\xc1\xff garbage",
        "decode.bad_header": prefix + msgpack.packb({"not": "a datagram"}),
        "decode.unknown_type": datagram(robot.fingerprint, 12345, ["x", []]),
        "decode.wrong_arity": datagram(
            robot.fingerprint, Note, ["text", [], 1, 1, 2, 0, 0, 0, "one too many"], header=()
        ),
        "decode.wrong_type": _raw_datagram(robot, 5, []),
        "decode.oversize": b"\x00" * 70_000,
        "cross_level": _raw_datagram(robot, "up", [], dst=1),
        "no_such_layer": _raw_datagram(robot, "deep", [], src=5, dst=5),
        "from_own_id": _raw_datagram(robot, "me", [], sender=1),
        "stack_mismatch": datagram(robot.fingerprint ^ 1, Note, ["x", []]),
        # Robot 3 is known, but the datagram comes from robot 2's address.
        "spoofed_sender": _raw_datagram(robot, "spoof", [], sender=3),
    }
    # From an address that is no robot's: refused before it is decoded.
    unknown = _raw_datagram(robot, "who", [], sender=77)
    host, port = robot.address
    transport.directory.add(3, "127.0.0.1", 9)  # never sent to
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        transport.directory.add(2, *sock.getsockname())  # the sender is robot 2
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
        for data in hostile.values():
            if len(data) <= 65_507:
                sock.sendto(data, (host, port))
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
            stranger.sendto(unknown, (host, port))
        sock.sendto(_raw_datagram(robot, "valid", [7]), (host, port))
    await wait_for(lambda: stack[0].external and sum(robot.dropped.values()) == len(hostile))
    expected = {reason: 1 for reason, data in hostile.items() if len(data) <= 65_507}
    expected["unknown_source"] = 1
    assert robot.dropped == expected
    assert [m.text for m in stack[0].external] == ["valid"]


@pytest.mark.cas_allow_drops("decode.oversize")
async def test_oversize_datagrams_are_refused_by_the_memory_transport_too(start_robot) -> None:
    transport = Tap()
    stack = recorders(1)
    robot = await start_robot(1, stack, transport=transport)
    await start_robot(2, recorders(1), transport=transport)
    transport.deliver(1, b"\x00" * 70_000, 2)
    assert robot.dropped == {"decode.oversize": 1}


@pytest.mark.cas_allow_drops("queue_full")
async def test_full_inbox_drops_external_messages(start_robot) -> None:
    transport = MemoryTransport()

    class Stuck(Layer):
        async def handle_msg(self, msg: Message) -> None:
            await asyncio.Event().wait()  # never returns: the inbox fills up

    receiver = await start_robot(1, [Stuck()], transport=transport, queue_limit=5)
    sender = recorders(1)
    await start_robot(2, sender, transport=transport)
    sender[0].send(1, Note("first", []))
    await wait_all_tasks_blocked()  # the layer is now stuck handling "first"
    for i in range(10):
        sender[0].send(1, Note(str(i), []))
    await wait_all_tasks_blocked()
    assert receiver.dropped == {"queue_full": 5}  # five wait in the inbox, five were refused
    assert receiver.inbox_sizes()[0] == 5


async def test_virtual_time_refuses_udp() -> None:
    robot = Robot(1, [Layer()], transport=UdpTransport(), clock=VirtualClock())
    with pytest.raises(ConfigurationError, match="VirtualClock needs the virtual-time event loop"):
        async with robot:
            pass


def test_virtual_time_with_udp_is_refused_on_the_virtual_loop() -> None:

    async def main() -> None:
        robot = Robot(1, [Layer()], transport=UdpTransport(), clock=VirtualClock())
        async with robot:
            pass

    with pytest.raises(ConfigurationError, match="real sockets, which do not run on virtual time"):
        cas_async.run(main(), virtual=True)


@pytest.mark.parametrize("use_uvloop", [False, True], ids=["stdlib", "uvloop"])
def test_two_robots_over_udp_on_each_event_loop(use_uvloop: bool) -> None:

    if use_uvloop and not cas_async.uvloop_available():
        pytest.skip("uvloop is not installed")

    async def main() -> list[int]:
        transport = UdpTransport()
        a, b = recorders(2), recorders(2)
        b[0].expected = 100
        async with (
            Robot(1, a, transport=transport, messages=STACK_MESSAGES),
            Robot(2, b, transport=transport, messages=STACK_MESSAGES) as robot_b,
        ):
            for i in range(100):
                a[0].send(2, Note(str(i), [i]))
                if i % 10 == 9:
                    await asyncio.sleep(0)
            await asyncio.wait_for(robot_b.run(), 5)
            answer = await a[1].request(2, Query(4), timeout=5)
            assert answer.value == 8
        return [m.hops[0] for m in b[0].external]

    assert cas_async.run(main(), use_uvloop=use_uvloop) == list(range(100))


@pytest.mark.cas_allow_drops("reply_from_wrong_place")
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
    await wait_all_tasks_blocked()
    (question,) = stack[1].negotiations
    forged = Answer(666, 0)  # robot 2 guesses the id of robot 1's internal request
    forged.msg_id, forged.robot_id, forged.corr_id = 7, 2, question.msg_id
    network.deliver(1, Codec.for_stack(2, STACK_MESSAGES).encode(forged), 2)  # from robot 2
    await wait_all_tasks_blocked()
    assert not asking.done()
    assert robot.dropped == {"reply_from_wrong_place": 1}
    asking.cancel()
    with pytest.raises(asyncio.CancelledError):
        await asking


@pytest.mark.cas_allow_drops("stack_mismatch")
async def test_a_flood_of_foreign_fingerprints_is_explained_a_few_times_only(
    start_robot, caplog
) -> None:
    tap = Tap()
    robot = await start_robot(1, recorders(1), transport=tap)
    for fingerprint in range(1000):
        tap.deliver(1, datagram(fingerprint, 1, []), 2)  # robot 2's
    explained = [r for r in caplog.records if "refusing datagrams" in r.getMessage()]
    assert len(explained) == 16
    assert robot.dropped == {"stack_mismatch": 1000}
    assert len(caplog.records) < 30


@pytest.mark.cas_allow_drops("stack_mismatch")
async def test_a_foreign_stack_is_blamed_on_its_source_not_on_the_robot_it_claims(
    start_robot, caplog
) -> None:
    tap = Tap()
    robot = await start_robot(1, recorders(1), transport=tap)
    tap.deliver(1, datagram(12345, 1, []), 3)  # claims 2, comes from 3
    (explained,) = [r.getMessage() for r in caplog.records if "refusing" in r.getMessage()]
    assert "refusing datagrams from robot 3:" in explained
    assert robot.dropped == {"stack_mismatch": 1}


@pytest.mark.cas_allow_drops("duplicate_reply")
async def test_late_and_duplicate_replies_are_dropped_not_counted_as_received(start_robot) -> None:
    transport = MemoryTransport()

    class Mute(Recorder):
        async def handle_msg(self, msg: Message) -> None:
            self.external.append(msg)

    asker, answerer = recorders(1), [Mute()]
    robot = await start_robot(1, asker, transport=transport)
    await start_robot(2, answerer, transport=transport)
    asking = asyncio.create_task(asker[0].request(2, Query(1), timeout=5))
    await wait_all_tasks_blocked()
    (question,) = answerer[0].external
    answerer[0].reply(question, Answer(2, 0))
    answerer[0].reply(question, Answer(2, 0))  # the same answer twice
    assert (await asking).value == 2
    await wait_all_tasks_blocked()
    answerer[0].reply(question, Answer(2, 0))  # and once more, later
    await wait_all_tasks_blocked()
    assert robot.dropped == {"duplicate_reply": 2}
    assert asker[0].counters.received_external == 1
    assert not asker[0].external


@message
class WideInt(Message):
    value: int


async def test_integers_beyond_64_bits_get_a_clear_encode_error(start_robot) -> None:
    stack = [Layer()]
    transport = MemoryTransport()
    await start_robot(1, stack, transport=transport, messages=[WideInt])
    await start_robot(2, [Layer()], transport=transport, messages=[WideInt])
    with pytest.raises(EncodeError, match=r"field .value.: can.t serialize ints"):
        stack[0].send(2, WideInt(2**70))
