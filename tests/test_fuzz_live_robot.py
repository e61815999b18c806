"""A robot completes its mission while an attacker floods it with hostile datagrams.

The victim (robot 1) asks its partner (robot 2) ``MISSION`` queries, one after the
other, and is done when every answer has arrived. Meanwhile an attacker, a plain
socket entered in the directory as robot 99 (a known address), sends hostile
datagrams of every kind in :data:`tests.fuzz_datagrams.KINDS` in bursts of one
kind; after each burst it waits until the victim has accounted for every datagram
sent (dropped and counted, or delivered to a hook), so each burst's outcome is
known exactly and the kernel never has to drop one. Nothing may be lost without a
count, nothing may crash, and the drop log must stay short. Run with ``-s`` to see
the table of outcomes by kind.
"""

from __future__ import annotations

import asyncio
import logging
import random
import socket
from collections import Counter
from collections.abc import Callable
from typing import Final

import pytest

import cas_async
from cas_async import (
    DecodeError,
    Layer,
    MemoryTransport,
    Message,
    MsgType,
    Robot,
    UdpTransport,
    VirtualClock,
)
from cas_async._core._dedup import ID_SLACK
from cas_async.transport import Codec
from tests.fuzz_datagrams import KINDS, HostileDatagrams, kinds_in_turn
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, Recorder

VICTIM: Final = 1
PARTNER: Final = 2
ATTACKER: Final = 99
MISSION: Final = 200
"""Queries the victim must get answered while under attack."""

_QUEUED_BYTES: Final = 16 * 1024
"""Bytes sent before the victim gets to read; a small socket buffer holds several times
that (asking 32 KiB gives 64 KiB), so the kernel has no reason to drop a datagram."""
_KERNEL_OVERHEAD: Final = 1024
"""About what the kernel charges a socket buffer per datagram besides its bytes."""

ACCEPTED: Final = "accepted"
"""The outcome of a hostile datagram delivered to a hook of the victim."""

DECODE = {f"decode.{reason}" for reason in DecodeError.REASONS} | {"stack_mismatch"}
# Outcomes each kind may have. The attacker's address is known (robot 99), so a
# datagram claiming another robot is a spoof: `spoofed_sender` (claims the partner
# or robot 12345) and `from_own_id` (claims the victim) are expected, never a hook.
# From an unknown address every kind would be `unknown_source`, refused undecoded.
EXPECTED: Final[dict[str, set[str]]] = {
    "random_bytes": DECODE,
    "truncated": {"decode.malformed"},
    "byte_flipped": DECODE
    | {ACCEPTED, "cross_level", "no_such_layer", "from_own_id", "spoofed_sender", "future_id"}
    | {"duplicate", "stale", "duplicate_reply", "late_reply", "reply_from_wrong_place"},
    "wrong_type_id": {"decode.unknown_type"},
    # A field too few or too many shifts the header that follows the fields.
    "wrong_field_types": {"decode.wrong_type", "decode.wrong_arity", "decode.bad_header"},
    # msgspec checks a value's type (its first byte) and an array's length against the
    # class before it reads what the length claims: a liar is often refused for those.
    "huge_lengths": {"decode.malformed", "decode.wrong_type", "decode.wrong_arity"},
    "wrong_fingerprint": {"stack_mismatch"},
    "wrong_level": {"cross_level", "no_such_layer"},
    "spoofed_sender": {"from_own_id", "spoofed_sender"},
    "valid": {ACCEPTED},
}


class Asker(Layer):
    """The victim's mission: queries to the partner, one at a time, as many as allowed."""

    def __init__(self) -> None:
        self.allowed = 0
        self.answered: list[int] = []
        self.wrong_answers: list[Message] = []
        self.unexpected: Counter[str] = Counter()

    def allow(self, queries: int) -> None:
        """Lets the mission go on to ``queries`` queries in all."""
        self.allowed = queries
        self.wake_after(0)

    async def inner_process(self) -> None:
        while len(self.answered) < min(self.allowed, MISSION):
            value = len(self.answered)
            reply = await self.request(PARTNER, Query(value), timeout=60)
            if not (isinstance(reply, Answer) and reply.value == 2 * value):
                self.wrong_answers.append(reply)  # a forged reply got through
            self.answered.append(value)

    async def handle_msg(self, msg: Message) -> None:
        self.unexpected[type(msg).__name__] += 1  # the mission sends no plain messages

    def termination_condition(self) -> bool:
        return len(self.answered) >= MISSION


class Responder(Layer):
    """The partner: answers the victim's queries; counts anything else."""

    def __init__(self) -> None:
        self.answers = 0
        self.unexpected: Counter[str] = Counter()

    async def handle_msg(self, msg: Message) -> None:
        if isinstance(msg, Query) and msg.msg_type == MsgType.NEGOTIATION:
            self.reply(msg, Answer(msg.value * 2, self.level))
            self.answers += 1
        else:
            self.unexpected[type(msg).__name__] += 1


def outcomes(victim: Robot, asker: Asker) -> Counter[str]:
    """Every datagram the victim has accounted for, by outcome (drop reason or hook)."""
    counts = Counter(victim.dropped)
    counts[ACCEPTED] = asker.unexpected.total()
    return counts


async def wait_until(condition: Callable[[], bool], seconds: float, explain: str) -> None:
    """Polls ``condition`` while datagrams travel (bounded by ``seconds`` of loop time)."""
    try:
        async with asyncio.timeout(seconds):
            while not condition():
                await asyncio.sleep(0.0005)
    except TimeoutError:
        raise AssertionError(f"not after {seconds} s: {explain()}") from None


async def all_accounted_for(victim: Robot, asker: Asker, sent: int) -> None:
    """Waits until the victim has dropped or delivered ``sent`` hostile datagrams."""
    await wait_until(
        lambda: outcomes(victim, asker).total() >= sent,
        10,
        lambda: f"{sent} sent, {outcomes(victim, asker).total()} accounted for",
    )


async def attack(
    victim: Robot,
    asker: Asker,
    send: Callable[[bytes], None],
    *,
    total: int,
    burst: int,
    seed: int,
) -> dict[str, Counter[str]]:
    """Sends ``total`` hostile datagrams in bursts of one kind; the outcomes by kind.

    After each burst the mission may ask one more query (spread over the attack).
    """
    rng = random.Random(seed)
    hostile = HostileDatagrams(
        Codec.for_stack(len(victim.layers), STACK_MESSAGES),
        rng,
        victim=VICTIM,
        attacker=ATTACKER,
        partner=PARTNER,
        levels=1,
        horizon=lambda: victim.clock.id_time() + ID_SLACK,
    )
    turns = kinds_in_turn(rng, total, burst)
    table: dict[str, Counter[str]] = {kind: Counter() for kind in KINDS}
    sent = 0
    for turn, kind in enumerate(turns):
        before = outcomes(victim, asker)
        count = min(burst, total - sent)
        queued = 0  # bytes the victim's socket buffer may hold since it last read
        for i in range(count):
            data = hostile.make(kind)
            send(data)
            queued += len(data) + _KERNEL_OVERHEAD
            if queued > _QUEUED_BYTES or i % 32 == 31:
                await asyncio.sleep(0)  # the victim reads: its socket buffer never fills
                queued = 0
        sent += count
        await all_accounted_for(victim, asker, sent)
        table[kind].update(outcomes(victim, asker) - before)
        asker.allow(MISSION * (turn + 1) // len(turns))
    return table


def check(table: dict[str, Counter[str]], victim: Robot, asker: Asker, total: int) -> None:
    """The assertions shared by both set-ups; prints the table of outcomes."""
    print(f"\n{'kind':<18} {'sent':>6}  outcomes")
    for kind, counts in table.items():
        shown = ", ".join(f"{reason} {n}" for reason, n in counts.most_common())
        print(f"{kind:<18} {counts.total():>6}  {shown}")
    print(f"victim dropped: {dict(sorted(victim.dropped.items()))}")
    # The mission is complete, and no forged answer reached it.
    assert asker.answered == list(range(MISSION))
    assert asker.wrong_answers == []
    # Every hostile datagram is accounted for exactly once: nothing lost uncounted.
    assert sum(victim.dropped.values()) + asker.unexpected.total() == total
    assert sum(counts.total() for counts in table.values()) == total
    # Every kind was sent, and ended only where it should.
    for kind, counts in table.items():
        assert counts.total() > 0, kind
        assert set(counts) <= EXPECTED[kind], (kind, counts)
    assert table["valid"][ACCEPTED] == table["valid"].total()


def logs_are_short(caplog: pytest.LogCaptureFixture) -> None:
    ours = [r for r in caplog.records if r.name.startswith("cas_async")]
    print(f"log records: {len(ours)}")
    crashes = [r for r in caplog.records if r.levelno >= logging.ERROR and r not in ours]
    assert crashes == []  # e.g. asyncio's "Exception in callback": a datagram crashed a reader
    assert len(ours) < 200, Counter(r.getMessage()[:60] for r in ours).most_common(10)


UDP_TOTAL: Final = 100_000


@pytest.mark.slow
async def test_mission_completes_under_100k_hostile_datagrams_over_udp(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING)
    transport = UdpTransport()
    attacker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    attacker.bind(("127.0.0.1", 0))
    attacker.setblocking(False)
    # Entered as robot 99: the victim knows who sends from this address.
    transport.directory.add(ATTACKER, *attacker.getsockname())
    asker, responder = Asker(), Responder()
    with attacker:
        async with (
            Robot(PARTNER, [responder], transport=transport, messages=STACK_MESSAGES),
            Robot(VICTIM, [asker], transport=transport, messages=STACK_MESSAGES) as victim,
        ):
            address = victim.address

            def send(data: bytes) -> None:
                attacker.sendto(data, address)  # loopback: the kernel never blocks it

            table = await attack(victim, asker, send, total=UDP_TOTAL, burst=500, seed=4)
            await asyncio.wait_for(victim.run(), 120)
            check(table, victim, asker, UDP_TOTAL)
    assert responder.unexpected.total() == 0
    logs_are_short(caplog)


MEMORY_TOTAL: Final = 20_000


def test_mission_completes_under_20k_hostile_datagrams_in_memory_on_virtual_time(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING)

    class Nobody:
        """The attacker's sink: the victim never answers it."""

        def datagram_received(self, data: bytes, sender: int | None = None) -> None:
            raise AssertionError("the victim sent the attacker something")

        def transport_dropped(self, reason: str, detail: str) -> None:
            raise AssertionError(f"lost on the way to the attacker: {reason}")

        def robot_joined(self, robot_id: int) -> None:
            """Membership news: not what these tests look at."""

        def robot_left(self, robot_id: int) -> None:
            """Membership news: not what these tests look at."""

    async def main() -> dict[str, Counter[str]]:
        transport = MemoryTransport()
        asker = Asker()
        async with (
            Robot(
                PARTNER,
                [Responder()],
                transport=transport,
                clock=VirtualClock(),
                messages=STACK_MESSAGES,
            ),
            Robot(
                VICTIM, [asker], transport=transport, clock=VirtualClock(), messages=STACK_MESSAGES
            ) as victim,
        ):
            endpoint = await transport.open(ATTACKER, Nobody())
            try:
                table = await attack(
                    victim,
                    asker,
                    lambda data: endpoint.send(VICTIM, data),
                    total=MEMORY_TOTAL,
                    burst=100,
                    seed=5,
                )
            finally:
                endpoint.close()
            await asyncio.wait_for(victim.run(), 120)
            check(table, victim, asker, MEMORY_TOTAL)
        return table

    table = cas_async.run(main(), virtual=True)
    assert cas_async.run(main(), virtual=True) == table  # virtual time: the same run again
    logs_are_short(caplog)


async def test_a_stranger_claiming_the_partner_cannot_silence_it() -> None:
    transport = UdpTransport()
    victim_layer, partner_layer = Recorder(), Recorder()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:
        stranger.bind(("127.0.0.1", 0))  # not in the directory: the transport cannot tell
        async with (
            Robot(PARTNER, [partner_layer], transport=transport, messages=STACK_MESSAGES),
            Robot(VICTIM, [victim_layer], transport=transport, messages=STACK_MESSAGES) as victim,
        ):
            forged = Note("forged", [])
            forged.msg_id, forged.robot_id = 2**63, PARTNER
            stranger.sendto(Codec.for_stack(1, STACK_MESSAGES).encode(forged), victim.address)

            def accounted() -> int:
                return sum(victim.dropped.values()) + len(victim_layer.external)

            await wait_until(lambda: accounted() == 1, 10, lambda: f"{victim.dropped}")
            partner_layer.send(VICTIM, Note("real", []))
            await wait_until(lambda: accounted() == 2, 10, lambda: f"{victim.dropped}")
            assert "real" in [m.text for m in victim_layer.external], victim.dropped
