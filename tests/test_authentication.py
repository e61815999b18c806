"""Authenticated datagrams: what verifies is delivered once, the rest is refused and counted."""

from __future__ import annotations

import asyncio
import hmac
import socket
from collections.abc import AsyncIterator, Iterable, Iterator

import pytest

from cas_async import (
    Address,
    AuthenticatedTransport,
    ConfigurationError,
    InsecureBindWarning,
    MemoryTransport,
    MsgType,
    Robot,
    RobotId,
    RobotStateError,
    SwarmKey,
    Transport,
    UdpTransport,
    UnknownRobotError,
)
from cas_async.testing import wait_all_tasks_blocked
from cas_async.transport import DatagramSink, Endpoint
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, recorders

TRAILER_SIZE = AuthenticatedTransport.TRAILER_SIZE
WINDOW = AuthenticatedTransport.WINDOW
KEY = SwarmKey(bytes(range(32)))
OTHER_KEY = SwarmKey(b"\xa5" * 32)


def sign(payload: bytes, sender: int, counter: int, receiver: int, key: SwarmKey = KEY) -> bytes:
    """The wire format, written out independently of the implementation."""
    head = payload + sender.to_bytes(8, "big", signed=True) + counter.to_bytes(8, "big")
    receiver_bytes = receiver.to_bytes(8, "big", signed=True)
    return head + hmac.new(key.secret, receiver_bytes + head, "sha256").digest()[:16]


def starts(*values: int) -> Iterator[int]:
    return iter(values)


class RecordingSink:
    """A DatagramSink that keeps everything it is told."""

    def __init__(self) -> None:
        self.received: list[tuple[bytes, RobotId | None]] = []
        self.dropped: list[tuple[str, str]] = []

    def datagram_received(self, data: bytes, sender: RobotId | None = None) -> None:
        self.received.append((data, sender))

    def transport_dropped(self, reason: str, detail: str) -> None:
        self.dropped.append((reason, detail))

    def robot_joined(self, robot_id: int) -> None:
        """Membership news: not what these tests look at."""

    def robot_left(self, robot_id: int) -> None:
        """Membership news: not what these tests look at."""

    @property
    def reasons(self) -> list[str]:
        return [reason for reason, _ in self.dropped]


class _TapEndpoint(Endpoint):
    def __init__(self, inner: Endpoint, log: list[tuple[RobotId, RobotId, bytes]]) -> None:
        self.robot_id = inner.robot_id
        self.max_datagram_size = inner.max_datagram_size
        self._inner = inner
        self._log = log

    @property
    def address(self) -> Address:
        return self._inner.address

    def send(self, robot_id: RobotId, data: bytes) -> None:
        self._log.append((self.robot_id, robot_id, data))
        self._inner.send(robot_id, data)

    def peers(self) -> Iterable[RobotId]:
        return self._inner.peers()

    def knows(self, robot_id: RobotId) -> bool:
        return self._inner.knows(robot_id)

    def close(self) -> None:
        self._inner.close()


class Tap(Transport):
    """Records every datagram its robots send (as a wiretapper on the network would)."""

    def __init__(self, inner: Transport) -> None:
        self.inner = inner
        self.supports_virtual_time = inner.supports_virtual_time
        self.sent: list[tuple[RobotId, RobotId, bytes]] = []

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        return _TapEndpoint(await self.inner.open(robot_id, sink), self.sent)


@pytest.fixture
async def endpoints() -> AsyncIterator[list[Endpoint]]:
    """Closes what a test opened."""
    opened: list[Endpoint] = []
    yield opened
    for endpoint in opened:
        endpoint.close()


async def _open(
    endpoints: list[Endpoint], transport: Transport, robot_id: RobotId, sink: DatagramSink
) -> Endpoint:
    endpoint = await transport.open(robot_id, sink)
    endpoints.append(endpoint)
    return endpoint


# -- a swarm sharing a key works as before ------------------------------------------------


async def test_robots_with_the_same_key_exchange_requests_and_replies(
    start_robot, cas_memory: MemoryTransport
) -> None:
    transport = AuthenticatedTransport(cas_memory, KEY)
    a, b = recorders(2), recorders(2)
    robot_a = await start_robot(1, a, transport=transport)
    robot_b = await start_robot(2, b, transport=transport)
    reply = await a[1].request(2, Query(21), timeout=5)
    a[0].send(2, Note("hello", []))
    await wait_all_tasks_blocked()
    assert isinstance(reply, Answer)
    assert (reply.value, reply.robot_id, reply.msg_type) == (42, 2, MsgType.ACCEPT)
    assert [m.text for m in b[0].external] == ["hello"]
    assert robot_a.dropped == robot_b.dropped == {}
    assert transport.stats == {
        "accepted": 3,
        "auth.too_short": 0,
        "auth.forged": 0,
        "auth.replay": 0,
        "auth.stale": 0,
    }


async def test_the_wrapper_marks_the_inner_transport_and_mirrors_virtual_time(
    cas_memory: MemoryTransport,
) -> None:
    assert not cas_memory.authenticated
    transport = AuthenticatedTransport(cas_memory, KEY)
    assert cas_memory.authenticated
    assert transport.authenticated
    assert transport.supports_virtual_time
    assert not AuthenticatedTransport(UdpTransport(), KEY).supports_virtual_time


async def test_the_trailer_is_the_documented_wire_format(
    cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    tap = Tap(cas_memory)
    transport = AuthenticatedTransport(tap, KEY, counter_start=starts(1000, 0).__next__)
    sender = await _open(endpoints, transport, -7, RecordingSink())
    sink = RecordingSink()
    await _open(endpoints, transport, 9, sink)
    sender.send(9, b"payload")
    sender.send(9, b"payload")  # every send takes a fresh counter
    await wait_all_tasks_blocked()
    assert [data for _, _, data in tap.sent] == [
        sign(b"payload", -7, 1001, 9),
        sign(b"payload", -7, 1002, 9),
    ]
    assert sink.received == [(b"payload", -7), (b"payload", -7)]


async def test_the_payload_limit_leaves_room_for_the_trailer(
    endpoints: list[Endpoint],
) -> None:
    transport = AuthenticatedTransport(MemoryTransport(max_datagram_size=1000), KEY)
    endpoint = await _open(endpoints, transport, 1, RecordingSink())
    assert TRAILER_SIZE == 32
    assert endpoint.max_datagram_size == 968


async def test_an_inner_transport_too_small_for_the_trailer_is_refused() -> None:
    inner = MemoryTransport(max_datagram_size=90)
    transport = AuthenticatedTransport(inner, KEY)
    with pytest.raises(ConfigurationError, match=r"robot 1: .* carries 90 bytes; .* at least 96"):
        await transport.open(1, RecordingSink())
    (await inner.open(1, RecordingSink())).close()  # the refused inner endpoint was closed


@pytest.mark.parametrize("robot_id", [2**63, -(2**63) - 1], ids=["too-big", "too-small"])
async def test_a_robot_id_beyond_8_bytes_is_refused(
    cas_memory: MemoryTransport, robot_id: int
) -> None:
    with pytest.raises(ConfigurationError, match=r"must be an int in -9223372036854775808\.\."):
        await AuthenticatedTransport(cas_memory, KEY).open(robot_id, RecordingSink())


async def test_sending_to_an_id_beyond_8_bytes_is_an_unknown_robot(
    cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    sender = await _open(endpoints, AuthenticatedTransport(cas_memory, KEY), 1, RecordingSink())
    await _open(endpoints, cas_memory, 2**63, RecordingSink())  # reachable, but not authenticated
    with pytest.raises(UnknownRobotError, match=r"robot 9223372036854775808 cannot be in an"):
        sender.send(2**63, b"hello")


def test_a_key_must_be_a_swarm_key(cas_memory: MemoryTransport) -> None:
    with pytest.raises(ConfigurationError, match="needs a SwarmKey, got bytes"):
        AuthenticatedTransport(cas_memory, KEY.secret)  # type: ignore[arg-type]
    with pytest.raises(ConfigurationError, match="max_senders must be at least 1, got 0"):
        AuthenticatedTransport(cas_memory, KEY, max_senders=0)


@pytest.mark.parametrize("start", [-1, 2**64], ids=["negative", "too-big"])
async def test_a_first_counter_beyond_8_unsigned_bytes_is_refused(
    cas_memory: MemoryTransport, start: int
) -> None:
    transport = AuthenticatedTransport(cas_memory, KEY, counter_start=lambda: start)
    with pytest.raises(ConfigurationError, match=rf"robot 1: first counter {start} is not in"):
        await transport.open(1, RecordingSink())


async def test_an_exhausted_counter_says_so(
    cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    transport = AuthenticatedTransport(cas_memory, KEY, counter_start=lambda: 2**64 - 2)
    sink = RecordingSink()
    await _open(endpoints, transport, 2, sink)
    sender = await _open(endpoints, transport, 1, RecordingSink())
    sender.send(2, b"last")
    with pytest.raises(RobotStateError, match="robot 1: the authentication counter is exhausted"):
        sender.send(2, b"one too many")
    await wait_all_tasks_blocked()
    assert sink.received == [(b"last", 1)]


# -- without the key nothing gets through ------------------------------------------------


@pytest.mark.cas_allow_drops("transport.auth.forged")
async def test_a_robot_with_another_key_is_refused_as_forged(
    start_robot, cas_memory: MemoryTransport
) -> None:
    ours, theirs = (
        AuthenticatedTransport(cas_memory, KEY),
        AuthenticatedTransport(cas_memory, OTHER_KEY),
    )
    a, b = recorders(1), recorders(1)
    robot_a = await start_robot(1, a, transport=theirs)
    robot_b = await start_robot(2, b, transport=ours)
    a[0].send(2, Note("let me in", []))
    b[0].send(1, Note("nor me", []))
    await wait_all_tasks_blocked()
    assert not a[0].external
    assert not b[0].external
    assert robot_a.dropped == robot_b.dropped == {"transport.auth.forged": 1}
    assert ours.stats["auth.forged"] == theirs.stats["auth.forged"] == 1


@pytest.mark.cas_allow_drops("transport.auth.forged", "decode.malformed")
async def test_a_robot_without_a_key_is_refused_and_refuses(
    start_robot, cas_memory: MemoryTransport
) -> None:
    keyed = AuthenticatedTransport(cas_memory, KEY)
    a, b = recorders(1), recorders(1)
    robot_a = await start_robot(1, a, transport=keyed)
    robot_b = await start_robot(2, b, transport=cas_memory)
    a[0].send(2, Note("signed", []))
    b[0].send(1, Note("unsigned", []))
    await wait_all_tasks_blocked()
    assert not a[0].external
    assert not b[0].external
    assert robot_a.dropped == {"transport.auth.forged": 1}
    # The trailer after the msgpack array makes it malformed msgpack: refused, counted.
    assert robot_b.dropped == {"decode.malformed": 1}


@pytest.mark.parametrize(
    "index",
    [0, -TRAILER_SIZE - 1, -TRAILER_SIZE, -24, -17, -16, -1],
    ids=["payload", "payload-end", "sender", "counter", "counter-end", "tag", "tag-end"],
)
async def test_an_altered_datagram_is_refused_as_forged(
    cas_memory: MemoryTransport, endpoints: list[Endpoint], index: int
) -> None:
    transport = AuthenticatedTransport(cas_memory, KEY)
    sink = RecordingSink()
    await _open(endpoints, transport, 2, sink)
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    datagram = bytearray(sign(b"some payload", 1, 500, 2))
    datagram[index] ^= 0x01
    attacker.send(2, bytes(datagram))
    attacker.send(2, sign(b"some payload", 1, 500, 2))  # the original still verifies
    await wait_all_tasks_blocked()
    assert sink.reasons == ["auth.forged"]
    assert "from the address of robot 66 does not verify" in sink.dropped[0][1]
    assert sink.received == [(b"some payload", 1)]


@pytest.mark.parametrize("size", [0, 1, TRAILER_SIZE - 1])
async def test_a_datagram_shorter_than_the_trailer_is_refused(
    cas_memory: MemoryTransport, endpoints: list[Endpoint], size: int
) -> None:
    transport = AuthenticatedTransport(cas_memory, KEY)
    sink = RecordingSink()
    await _open(endpoints, transport, 2, sink)
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    attacker.send(2, sign(b"", 1, 5, 2)[:size])
    await wait_all_tasks_blocked()
    assert sink.reasons == ["auth.too_short"]
    assert transport.stats["auth.too_short"] == 1


@pytest.mark.parametrize("cut", [1, 16], ids=["last-byte", "tag"])
async def test_a_truncated_datagram_is_refused_as_forged(
    cas_memory: MemoryTransport, endpoints: list[Endpoint], cut: int
) -> None:
    transport = AuthenticatedTransport(cas_memory, KEY)
    sink = RecordingSink()
    await _open(endpoints, transport, 2, sink)
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    attacker.send(2, sign(b"a payload long enough", 1, 5, 2)[:-cut])
    await wait_all_tasks_blocked()
    assert sink.reasons == ["auth.forged"]
    assert not sink.received


# -- replays -------------------------------------------------------------------------------


@pytest.mark.cas_allow_drops("transport.auth.replay")
async def test_a_recorded_datagram_sent_again_is_refused_as_replay(
    start_robot, cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    tap = Tap(cas_memory)
    transport = AuthenticatedTransport(tap, KEY)
    a, b = recorders(1), recorders(1)
    await start_robot(1, a, transport=transport)
    robot_b = await start_robot(2, b, transport=transport)
    a[0].send(2, Note("once", []))
    await wait_all_tasks_blocked()
    ((_, _, recorded),) = tap.sent
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    attacker.send(2, recorded)
    attacker.send(2, recorded)
    await wait_all_tasks_blocked()
    assert [m.text for m in b[0].external] == ["once"]
    assert robot_b.dropped == {"transport.auth.replay": 2}


@pytest.mark.cas_allow_drops("transport.auth.forged")
async def test_a_datagram_for_one_robot_does_not_verify_at_another(
    start_robot, cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    tap = Tap(cas_memory)
    transport = AuthenticatedTransport(tap, KEY)
    a, b, c = recorders(1), recorders(1), recorders(1)
    await start_robot(1, a, transport=transport)
    await start_robot(2, b, transport=transport)
    robot_c = await start_robot(3, c, transport=transport)
    a[0].send(2, Note("for 2 only", []))
    await wait_all_tasks_blocked()
    ((_, _, recorded),) = tap.sent
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    attacker.send(3, recorded)  # robot 3 never saw counter: only the tag can tell
    attacker.send(1, recorded)  # nor is it accepted back at its sender
    await wait_all_tasks_blocked()
    assert not c[0].external
    assert not a[0].external
    assert robot_c.dropped == {"transport.auth.forged": 1}


async def test_reordering_within_the_window_is_accepted_and_older_is_stale(
    cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    transport = AuthenticatedTransport(cas_memory, KEY)
    sink = RecordingSink()
    await _open(endpoints, transport, 2, sink)
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    newest = 5000
    oldest_in_window = newest - WINDOW + 1
    order = [
        (100, None),
        (105, None),
        (101, None),  # late, but inside the window
        (103, None),
        (105, "auth.replay"),
        (101, "auth.replay"),
        (newest, None),
        (oldest_in_window, None),
        (oldest_in_window - 1, "auth.stale"),
        (105, "auth.stale"),
        (newest, "auth.replay"),
        (newest - 1, None),
    ]
    for counter, _ in order:
        attacker.send(2, sign(counter.to_bytes(4, "big"), 1, counter, 2))
    await wait_all_tasks_blocked()
    accepted = [int.from_bytes(data, "big") for data, _ in sink.received]
    assert accepted == [counter for counter, refusal in order if refusal is None]
    assert sink.reasons == [refusal for _, refusal in order if refusal is not None]
    assert "counter 3976 is 1024 behind the newest (5000)" in sink.dropped[2][1]


async def test_a_jump_far_ahead_forgets_the_window(
    cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    transport = AuthenticatedTransport(cas_memory, KEY)
    sink = RecordingSink()
    await _open(endpoints, transport, 2, sink)
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    top = 2**64 - 1
    for counter in (10, top, top - 1, 10, top - WINDOW):
        attacker.send(2, sign(b"", 1, counter, 2))
    await wait_all_tasks_blocked()
    assert len(sink.received) == 3  # 10, the top and the one just below it
    assert sink.reasons == ["auth.stale", "auth.stale"]


async def test_a_restarted_robot_is_accepted(start_robot, cas_memory: MemoryTransport) -> None:
    # Robot 1 lives twice; its second life starts counting above where the first stopped.
    first_life = AuthenticatedTransport(cas_memory, KEY, counter_start=lambda: 1_000)
    second_life = AuthenticatedTransport(cas_memory, KEY, counter_start=lambda: 2_000)
    b = recorders(1)
    robot_b = await start_robot(2, b, transport=AuthenticatedTransport(cas_memory, KEY))
    for transport, text in ((first_life, "before"), (second_life, "after")):
        a = recorders(1)
        async with Robot(1, a, transport=transport, messages=STACK_MESSAGES):
            a[0].send(2, Note(text, []))
            await wait_all_tasks_blocked()
    assert [m.text for m in b[0].external] == ["before", "after"]
    assert robot_b.dropped == {}


async def test_a_restart_that_counts_from_below_is_taken_for_a_replay(
    cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    # The documented assumption: counters start from the wall clock, which must not step back.
    transport = AuthenticatedTransport(cas_memory, KEY, counter_start=lambda: 1_000)
    sink = RecordingSink()
    await _open(endpoints, AuthenticatedTransport(cas_memory, KEY), 2, sink)
    for _ in range(2):
        sender = await transport.open(1, RecordingSink())
        sender.send(2, b"hi")
        sender.close()
    await wait_all_tasks_blocked()
    assert sink.received == [(b"hi", 1)]
    assert sink.reasons == ["auth.replay"]


@pytest.mark.cas_allow_drops("spoofed_sender")
async def test_a_key_holder_cannot_claim_another_robots_id_in_the_header(
    start_robot, cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    tap = Tap(cas_memory)
    transport = AuthenticatedTransport(tap, KEY)
    a, b = recorders(1), recorders(1)
    await start_robot(1, a, transport=transport)
    robot_b = await start_robot(2, b, transport=transport)
    await start_robot(3, recorders(1), transport=transport)
    a[0].send(2, Note("from 1", []))
    await wait_all_tasks_blocked()
    ((_, _, recorded),) = tap.sent
    # Robot 3 holds the key and re-signs robot 1's message as its own.
    payload = recorded[:-TRAILER_SIZE]
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    attacker.send(2, sign(payload, 3, 10**18, 2))
    await wait_all_tasks_blocked()
    assert [m.text for m in b[0].external] == ["from 1"]
    assert robot_b.dropped == {"spoofed_sender": 1}


# -- cas_memory: forged datagrams cannot grow state --------------------------------------------


async def test_forged_datagrams_do_not_take_places_in_the_sender_table(
    cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    # One place only: if forged datagrams took places, robot 1 would be evicted and its
    # recorded datagram accepted again.
    transport = AuthenticatedTransport(cas_memory, KEY, max_senders=1)
    sink = RecordingSink()
    await _open(endpoints, transport, 2, sink)
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    recorded = sign(b"genuine", 1, 77, 2)
    attacker.send(2, recorded)
    for claimed in range(100, 1100):
        attacker.send(2, sign(b"forged", claimed, 1, 2, key=OTHER_KEY))
    attacker.send(2, recorded)
    await wait_all_tasks_blocked()
    assert sink.received == [(b"genuine", 1)]
    assert transport.stats["auth.forged"] == 1000
    assert sink.reasons[-1] == "auth.replay"


async def test_the_least_recently_heard_sender_is_forgotten_beyond_the_bound(
    cas_memory: MemoryTransport, endpoints: list[Endpoint]
) -> None:
    transport = AuthenticatedTransport(cas_memory, KEY, max_senders=2)
    sink = RecordingSink()
    await _open(endpoints, transport, 2, sink)
    attacker = await _open(endpoints, cas_memory, 66, RecordingSink())
    for sender, counter in ((1, 10), (3, 10), (1, 11), (4, 10)):  # 3 is heard least recently
        attacker.send(2, sign(b"", sender, counter, 2))
    attacker.send(2, sign(b"", 1, 11, 2))  # still tracked: a replay
    attacker.send(2, sign(b"", 3, 10, 2))  # forgotten: taken as new (documented limit)
    await wait_all_tasks_blocked()
    assert [sender for _, sender in sink.received] == [1, 3, 1, 4, 3]
    assert sink.reasons == ["auth.replay"]


# -- over real UDP -------------------------------------------------------------------------


async def _until(condition, timeout: float = 5.0) -> None:
    """Polls while real datagrams travel (bounded; no timed assertion)."""
    async with asyncio.timeout(timeout):
        while not condition():
            await asyncio.sleep(0.001)


@pytest.mark.cas_allow_drops("transport.auth.replay", "transport.auth.forged")
async def test_over_udp_requests_work_and_a_raw_replay_is_refused(start_robot) -> None:
    udp = UdpTransport()
    tap = Tap(udp)
    transport = AuthenticatedTransport(tap, KEY)
    a, b = recorders(1), recorders(1)
    await start_robot(1, a, transport=transport)
    robot_b = await start_robot(2, b, transport=transport)
    reply = await a[0].request(2, Query(4), timeout=5)
    assert (reply.value, reply.robot_id) == (8, 2)
    request = next(data for source, _, data in tap.sent if source == 1)
    address = udp.directory.get(2)
    assert address is not None
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
        raw.sendto(request, address)
        raw.sendto(request[:-1] + bytes([request[-1] ^ 1]), address)
        await _until(lambda: sum(robot_b.dropped.values()) >= 2)
    assert robot_b.dropped == {"transport.auth.replay": 1, "transport.auth.forged": 1}
    assert len(b[0].external) == 1


# -- UDP beyond loopback warns without a key -----------------------------------------------


async def test_binding_beyond_loopback_without_a_key_warns() -> None:
    transport = UdpTransport(host="0.0.0.0")
    with pytest.warns(
        InsecureBindWarning,
        match=r"robot 5: UDP socket bound to 0\.0\.0\.0 port \d+ .* without authentication; "
        r".*CAS_ASYNC_SWARM_KEY=<hex> or a key file.* AuthenticatedTransport",
    ):
        endpoint = await transport.open(5, RecordingSink())
    endpoint.close()


async def test_a_warning_made_an_error_leaves_no_socket_behind() -> None:
    transport = UdpTransport(host="0.0.0.0")
    with pytest.raises(InsecureBindWarning):  # pytest runs with warnings as errors
        await transport.open(5, RecordingSink())
    assert 5 not in transport.directory
    with pytest.warns(InsecureBindWarning):  # and the robot may be opened again
        endpoint = await transport.open(5, RecordingSink())
    endpoint.close()


@pytest.mark.parametrize("host", ["0.0.0.0", "127.0.0.1"], ids=["any-with-key", "loopback"])
async def test_no_warning_with_a_key_or_on_loopback(host: str) -> None:
    udp = UdpTransport(host=host)
    transport: Transport = AuthenticatedTransport(udp, KEY) if host == "0.0.0.0" else udp
    # Warnings are errors here: opening without one is the assertion.
    endpoint = await transport.open(5, RecordingSink())
    endpoint.close()
