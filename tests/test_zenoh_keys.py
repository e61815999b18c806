"""The keys of robots that talk are declared to Zenoh, within a budget, and undeclared in time.

Real sessions on loopback. A publisher per pair to send, a key expression per pair to
receive (``cas_async.transport.zenoh._keys`` says what each saves); what is declared
stays bounded whatever strangers publish, goes when a robot of the pair goes, and a
pair beyond the budget still gets every datagram through.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from cas_async import ZenohTransport
from cas_async.transport.zenoh._keys import KNOWN_KEYS, Publishers, ReceivedKeys
from cas_async.transport.zenoh._sessions import loopback_config
from tests.stacks import Note, Recorder, recorders
from tests.zenoh_support import (
    Sink,
    admin_config,
    datagram,
    listener,
    locators,
    namespace,
    publish,
    reachable,
    robot,
    stranger,
    texts,
    until,
)

zenoh = pytest.importorskip("zenoh")


async def test_robots_that_talk_declare_their_keys_and_drop_them_when_one_leaves() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        assert home.declared_keys() == (0, 0)
        a = recorders(2)
        async with robot(1, a, home):
            await talk_with_robot_2(home, endpoint, a, "first")
            await talk_with_robot_2(home, endpoint, a, "back in a new session")
            assert texts(a[0]) == ["to 1, first", "to 1, back in a new session"]
        assert home.dropped == {}


async def talk_with_robot_2(
    home: ZenohTransport, endpoint: str, a: list[Recorder], when: str
) -> None:
    """Robot 2 joins in a session of its own, trades a note with robot 1, and leaves."""
    away = ZenohTransport(namespace=home.namespace, connect=[endpoint])
    b = recorders(2)
    async with robot(2, b, away):
        await until(lambda: a[0].knows(2) and b[0].knows(1))
        a[0].send(2, Note(f"to 2, {when}", []))
        b[0].send(1, Note(f"to 1, {when}", []))
        await until(lambda: f"to 1, {when}" in texts(a[0]) and texts(b[0]))
        assert texts(b[0]) == [f"to 2, {when}"]
        assert home.declared_keys() == (1, 1)  # 1 -> 2 to send, 2 -> 1 to receive
        assert away.declared_keys() == (1, 1)
    await until(lambda: not a[0].knows(2), "robot 2's token goes")
    assert home.declared_keys() == (0, 0)
    assert away.session is None


async def test_keys_strangers_make_up_are_not_declared() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        sink = Sink()
        receiver = await home.open(1, sink)
        try:
            here = f"{ns}/d/{home.zid}/1"
            async with stranger(endpoint) as session:
                await reachable(session, f"{here}/500")
                for sender in range(500, 520):  # no token speaks for any of them
                    publish(session, f"{here}/{sender}", datagram("made up", sender))
                await until(lambda: len(sink.received) == 20, lambda: sink.received)
            assert {sender for _, sender in sink.received} == {None}  # refused by the robot
            assert home.declared_keys() == (0, 0)
        finally:
            receiver.close()


@pytest.fixture
async def two_sessions() -> Any:
    """Two raw sessions on loopback, the second connected to the first; both closed after."""
    first = await asyncio.to_thread(zenoh.open, admin_config())
    try:
        (endpoint,) = await asyncio.to_thread(locators, first)
        second = await asyncio.to_thread(zenoh.open, loopback_config(listen=[], connect=[endpoint]))
        try:
            yield first, second
        finally:
            second.close()
    finally:
        first.close()


async def test_pairs_beyond_the_budget_put_through_the_session_and_get_there(
    two_sessions: Any,
) -> None:
    receiving, sending = two_sessions
    ns = namespace()
    got: list[tuple[str, bytes]] = []
    subscriber = receiving.declare_subscriber(
        f"{ns}/d/zid/*/*",
        lambda sample: got.append((str(sample.key_expr), sample.payload.to_bytes())),
    )
    try:
        publishers = Publishers(zenoh, sending, ns, budget=2)
        await reachable(sending, f"{ns}/d/zid/9/1")
        for sender in (1, 2, 3):
            publishers.put_for("zid", 9, sender)(b"from %d" % sender)
        assert publishers.declared() == 2  # the third pair puts through the session
        await until(lambda: len(got) == 3, lambda: got)
        assert sorted(got) == [(f"{ns}/d/zid/9/{n}", b"from %d" % n) for n in (1, 2, 3)]
        publishers.forget_sender(1)
        assert publishers.declared() == 1
        publishers.put_for("zid", 9, 4)(b"from 4")  # the freed place goes to the next pair
        assert publishers.declared() == 2
        publishers.forget_receiver(9)
        assert publishers.declared() == 0
        publishers.put_for("other", 9, 2)(b"elsewhere")  # a new session: a new key
        assert publishers.declared() == 1
        await until(lambda: len(got) == 4, lambda: got)
        assert got[-1] == (f"{ns}/d/zid/9/4", b"from 4")
    finally:
        subscriber.undeclare()


async def test_received_keys_are_read_once_declared_within_the_budget_and_stay_bounded(
    two_sessions: Any,
) -> None:
    receiving, _ = two_sessions
    keys = ReceivedKeys(receiving, budget=2)
    assert keys.read("ns/d/zid/7/3") == (7, 3)
    assert keys.pairs == {"ns/d/zid/7/3": (7, 3)}
    for bad in ("ns/d/zid/7/three", "ns/d/zid/seven/3", "ns/d/zid/7"):
        assert keys.read(bad) is None
    for sender in (3, 4, 5):
        keys.declare(f"ns/d/zid/7/{sender}", (7, sender))
    keys.declare("ns/d/zid/7/3", (7, 3))  # once only
    assert keys.declared() == 2
    keys.forget(3)  # robot 3 left (or joined): its keys are read again, and undeclared
    assert keys.declared() == 1
    assert "ns/d/zid/7/3" not in keys.pairs
    keys.declare("ns/d/zid/8/9", (8, 9))
    keys.forget(7)  # as receiver too
    assert keys.declared() == 1
    for n in range(KNOWN_KEYS + 10):
        keys.read(f"ns/d/zid/1/{n}")
    assert 0 < len(keys.pairs) <= KNOWN_KEYS
