"""A stranger on the Zenoh network, with a session of its own and no key, against real robots.

The stranger is a raw Zenoh session on loopback connected to where the robots'
session listens (``tests.zenoh_support.stranger``). It reads every token, declares
forged ones (a placed robot's id at a session that does not exist, held, then let
go), copies real ones, puts garbage under robots' keys, and floods. The robots must
keep talking: no robot becomes unreachable, and every refusal is counted, in the
transport and in the robots' drops. The rules themselves: ``test_zenoh_members``.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
from collections.abc import Iterator
from typing import Any

import pytest

from cas_async import (
    AuthenticatedTransport,
    ConfigurationError,
    SwarmKey,
    Transport,
    ZenohTransport,
)
from tests.stacks import Answer, Query, Recorder, recorders
from tests.test_zenoh_transport import spawn, stop
from tests.zenoh_support import Sink, listener, namespace, publish, robot, stranger, until

zenoh = pytest.importorskip("zenoh")

KEY = SwarmKey(bytes(range(32)))
FAKE = "0123456789abcdef" * 2  # a session that does not exist
SIGNED = re.compile(r"(?P<head>.+/alive/\d+/)(?P<zid>[0-9a-f]+)(?P<tail>/\d+/[0-9a-f]{32})")


def tokens(session: Any, ns: str) -> set[str]:
    """Every live token under ``ns``, as a stranger's one query sees them (blocking)."""
    return {str(reply.ok.key_expr) for reply in session.liveliness().get(f"{ns}/**", timeout=5.0)}


async def token_with(session: Any, ns: str, part: str) -> str:
    """The one token under ``ns`` with ``part`` in its key, once the stranger sees it.

    A peer does not pass on another peer's tokens: the stranger sees those of a
    session it is not connected to once Zenoh's gossip has connected the two.
    """
    for _ in range(100):  # 10 s at most
        found = [key for key in await asyncio.to_thread(tokens, session, ns) if part in key]
        if found:
            (key,) = found
            return key
        await asyncio.sleep(0.1)
    raise AssertionError(f"no token with {part!r} under {ns!r}")


@contextlib.contextmanager
def declared(session: Any, keys: list[str]) -> Iterator[list[Any]]:
    """Liveliness tokens ``session`` holds under ``keys`` until the block ends."""
    held = []
    try:
        for key in keys:
            held.append(session.liveliness().declare_token(key))
        yield held
    finally:
        for token in held:
            token.undeclare()


async def flushed(session: Any, transport: ZenohTransport) -> None:
    """Returns once ``transport`` has drained all that ``session`` did before this call.

    A datagram for a robot that is nowhere (counted as ``no_receiver``) goes behind
    the stranger's tokens: they are queued before any datagram that follows them.
    """
    before = transport.dropped.get("no_receiver", 0)
    key = f"{transport.namespace}/d/{transport.zid}/999999/1"
    publish(session, key, b"marker")
    await until(lambda: transport.dropped.get("no_receiver", 0) > before, "the marker datagram")


async def ask(asker: Recorder, robot_id: int, value: int = 21) -> None:
    """Robot ``robot_id`` answers a request, so it is reachable."""
    reply = await asker.request(robot_id, Query(value), timeout=5)
    assert isinstance(reply, Answer)
    assert (reply.value, reply.robot_id) == (2 * value, robot_id)


def signed(transport: Transport) -> Transport:
    return AuthenticatedTransport(transport, KEY)


# -- without a key ---------------------------------------------------------------------------


async def test_forged_tokens_neither_move_nor_remove_robots_of_one_process() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        a, b, c = recorders(2), recorders(2), recorders(2)
        async with (
            robot(1, a, home) as robot_1,
            robot(2, b, home) as robot_2,
            robot(3, c, home) as robot_3,
            stranger(endpoint) as session,
        ):
            seen = await asyncio.to_thread(tokens, session, ns)
            assert seen == {f"{ns}/alive/{n}/{home.zid}" for n in (1, 2, 3)}
            with declared(session, [f"{ns}/alive/2/{FAKE}", f"{ns}/alive/3/{FAKE}"]):
                await until(lambda: home.dropped.get("token_conflict") == 2, lambda: home.dropped)
                await ask(a[0], 3)
                await ask(c[0], 2)
            await flushed(session, home)  # the forged tokens went
            assert sorted(home.members()) == [1, 2, 3]
            assert {home.zid_of(n) for n in (1, 2, 3)} == {home.zid}
            await ask(a[0], 3)
            await ask(b[0], 1)
            assert robot_1.dropped == {}
            conflict = {"transport.token_conflict": 1}
            assert robot_2.dropped == robot_3.dropped == conflict
        assert home.dropped == {"token_conflict": 2, "no_receiver": 1}


async def test_a_forged_token_leaves_a_robot_of_another_process_where_it_is() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        stack = recorders(2)
        async with robot(1, stack, home) as robot_1, stranger(endpoint) as session:
            peer = await spawn("talk", ns, endpoint, 2)  # its own OS process
            try:
                await until(lambda: stack[0].knows(2), "the peer's robot", timeout=20)
                there = home.zid_of(2)
                with declared(session, [f"{ns}/alive/2/{FAKE}"]):
                    await until(lambda: home.dropped.get("token_conflict"), lambda: home.dropped)
                    await ask(stack[0], 2)
                await flushed(session, home)
                assert home.zid_of(2) == there
                await ask(stack[0], 2)
            finally:
                await stop(peer)
            assert "unknown_robot" not in robot_1.dropped
            assert robot_1.dropped == {"transport.token_conflict": 1}  # the first robot here


# -- with a key ------------------------------------------------------------------------------


async def test_with_a_key_a_stranger_can_neither_place_move_nor_remove_a_robot() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        a, b = recorders(2), recorders(2)
        async with (
            robot(1, a, signed(home)) as robot_1,
            robot(2, b, signed(away)),
            stranger(endpoint) as session,
        ):
            await until(lambda: a[0].knows(2) and b[0].knows(1))
            robot_2_key = await token_with(session, ns, f"/alive/2/{away.zid}/")
            match = SIGNED.fullmatch(robot_2_key)
            assert match is not None  # signed: stamped, with a proof
            forged = [
                f"{ns}/alive/2/{FAKE}",  # unsigned, for a placed robot
                f"{ns}/alive/9/{FAKE}",  # unsigned, for a robot that does not exist
                f"{match['head']}{FAKE}{match['tail']}",  # robot 2's proof, another session
                robot_2_key,  # an exact copy: Zenoh merges it with the real one
            ]
            with declared(session, forged):
                await until(lambda: len(home.dropped) >= 2, lambda: home.dropped)
                await ask(a[0], 2)
            await flushed(session, home)
            assert home.dropped == {"token_unsigned": 2, "token_forged": 1, "no_receiver": 1}
            assert sorted(home.members()) == [1, 2]
            assert home.zid_of(2) == away.zid
            await ask(a[0], 2)
            assert robot_1.dropped == {"transport.token_unsigned": 2, "transport.token_forged": 1}
        # Robot 2 left: a copy of its token does not bring it back.
        async with robot(1, recorders(2), signed(home)), stranger(endpoint) as session:
            with declared(session, [robot_2_key]):
                await until(lambda: home.dropped.get("token_replayed"), lambda: home.dropped)
            assert home.members() == [1]


async def test_with_a_key_a_robot_restarted_elsewhere_moves_there_at_once() -> None:
    # Its old process still holds its token (frozen, say: Zenoh's lease is 10 s): the
    # newer signed token wins, and the old process counts the conflict.
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        old, new = (ZenohTransport(namespace=ns, connect=[endpoint]) for _ in range(2))
        a, stale, fresh = recorders(2), recorders(2), recorders(2)
        async with robot(1, a, signed(home)), robot(2, stale, signed(old)) as robot_old:
            await until(lambda: home.zid_of(2) == old.zid)
            async with robot(2, fresh, signed(new)):
                await until(lambda: home.zid_of(2) == new.zid, lambda: home.zid_of(2))
                await ask(a[0], 2)
                assert [type(m) for m in fresh[0].external] == [Query]
                assert stale[0].external == []
                await until(lambda: robot_old.dropped, "the old process sees the conflict")
                assert robot_old.dropped == {"transport.token_conflict": 1}
            await until(lambda: home.zid_of(2) is None, "the newer robot 2 left")
        assert home.dropped == {}


async def test_a_stranger_that_copies_a_token_keeps_a_gone_robot_looking_present() -> None:
    # What a stranger can still do with a key in place (documented): hold a copy of a
    # live robot's token, so that its going is not seen until the copy goes too.
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        async with robot(1, recorders(2), signed(home)), stranger(endpoint) as session:
            async with robot(2, recorders(2), signed(away)):
                await until(lambda: home.zid_of(2) == away.zid)
                there = away.zid
                key = await token_with(session, ns, f"/alive/2/{away.zid}/")
                copy = session.liveliness().declare_token(key)
                await flushed(session, home)  # the copy is there before robot 2 goes
            try:
                await asyncio.sleep(0.2)  # robot 2's session closed: its token went
                assert away.session is None
                assert home.zid_of(2) == there  # gone, but looks present
            finally:
                copy.undeclare()
            await until(lambda: home.zid_of(2) is None, "robot 2 leaves with the copy")


# -- what must keep working -------------------------------------------------------------------


@pytest.mark.parametrize("keyed", [False, True], ids=["no key", "key"])
async def test_a_robot_that_leaves_and_comes_back_in_another_session_is_placed_there(
    keyed: bool,
) -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        a = recorders(2)
        wire = signed(home) if keyed else home
        async with robot(1, a, wire) as robot_1:
            zids = []
            for _ in range(3):  # a restart: a new process, a new session
                away = ZenohTransport(namespace=ns, connect=[endpoint])
                async with robot(2, recorders(2), signed(away) if keyed else away):
                    await until(lambda away=away: home.zid_of(2) == away.zid, "robot 2 comes")
                    zids.append(away.zid)
                    await ask(a[0], 2)
                await until(lambda: home.zid_of(2) is None, "robot 2 leaves")
            assert len(set(zids)) == 3
            assert robot_1.dropped == {}
        assert home.dropped == {}


# -- floods ----------------------------------------------------------------------------------


@pytest.mark.parametrize("keyed", [False, True], ids=["no key", "key"])
async def test_a_flood_of_tokens_and_garbage_leaves_the_robots_talking(keyed: bool) -> None:
    ns = namespace()
    forged_for_2, new_robots, garbage = 100, 50, 2000
    async with listener(ns) as (home, endpoint):
        wire = signed(home) if keyed else home
        a, b = recorders(2), recorders(2)
        async with (
            robot(1, a, wire) as robot_1,
            robot(2, b, wire),
            stranger(endpoint) as session,
        ):
            forged = [f"{ns}/alive/2/{n:032x}" for n in range(1, forged_for_2 + 1)]
            forged += [f"{ns}/alive/{1000 + n}/{FAKE}" for n in range(new_robots)]
            forged += [f"{ns}/alive/{n}" for n in range(20)]  # malformed
            with declared(session, forged):
                for n in range(garbage):
                    publish(session, f"{ns}/d/{home.zid}/1/2", b"\xc1garbage" * (1 + n % 7))
                await ask(a[0], 2)
                await ask(b[0], 1)
                await flushed(session, home)
                assert home.zid_of(2) == home.zid
                assert len(home.members()) == (2 if keyed else 2 + new_robots)
            await flushed(session, home)
            assert sorted(home.members()) == [1, 2]
            await ask(a[0], 2)
        refused = home.dropped
        if keyed:
            assert refused["token_unsigned"] == forged_for_2 + new_robots
        else:  # without a key a stranger can add robots that do not exist
            assert refused["token_conflict"] == forged_for_2
        assert refused["token_malformed"] == 20
        drops = robot_1.dropped
        assert drops["transport.token_malformed"] == 20
        assert sum(n for reason, n in drops.items() if reason != "transport.token_malformed") >= (
            garbage
        )
        assert "unknown_robot" not in drops


async def test_a_transport_is_given_its_key_before_its_robots_open() -> None:
    transport = ZenohTransport(namespace=namespace())
    endpoint = await transport.open(1, Sink())
    try:
        with pytest.raises(
            ConfigurationError,
            match=r"wrap the ZenohTransport in AuthenticatedTransport before opening robots: "
            r"robots \[1\] have unsigned tokens already",
        ):
            AuthenticatedTransport(transport, KEY)
        assert not transport.authenticated
    finally:
        endpoint.close()
