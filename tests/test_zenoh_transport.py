"""ZenohTransport on real Zenoh sessions, on loopback only.

Every test opens its own sessions under its own namespace (so no test sees another's
robots), closes them before it ends, and waits for the network only with a bound
(helpers in ``tests.zenoh_support``; the keys' declarations in ``test_zenoh_keys``).
"""

from __future__ import annotations

import asyncio
import functools
import hmac
import os
import re
import signal
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

import cas_async
from cas_async import (
    AuthenticatedTransport,
    ConfigurationError,
    InsecureBindWarning,
    MsgType,
    RobotGone,
    RobotId,
    RobotStateError,
    SwarmKey,
    Transport,
    UnknownRobotError,
    VirtualClock,
    ZenohTransport,
)
from cas_async.transport.zenoh._transport import loopback_config
from tests.stacks import Answer, Note, Query, Recorder, recorders
from tests.zenoh_support import (
    Sink,
    datagram,
    listener,
    namespace,
    os_threads,
    publish,
    python_threads,
    reachable,
    robot,
    stranger,
    texts,
    until,
)

zenoh = pytest.importorskip("zenoh")

ROOT = Path(__file__).resolve().parent.parent
KEY = SwarmKey(bytes(range(32)))
OTHER_KEY = SwarmKey(b"\xa5" * 32)
PAYLOAD = "x" * 1000


# -- helpers ---------------------------------------------------------------------------------


def sign(payload: bytes, sender: int, counter: int, receiver: int, key: SwarmKey) -> bytes:
    """AuthenticatedTransport's wire format, written out independently."""
    head = payload + sender.to_bytes(8, "big", signed=True) + counter.to_bytes(8, "big")
    receiver_bytes = receiver.to_bytes(8, "big", signed=True)
    return head + hmac.new(key.secret, receiver_bytes + head, "sha256").digest()[:16]


class Watcher(Recorder):
    """A recorder that notes who joins and leaves."""

    def __init__(self) -> None:
        super().__init__()
        self.news: list[tuple[str, RobotId]] = []

    async def on_robot_joined(self, robot_id: RobotId) -> None:
        self.news.append(("joined", robot_id))

    async def on_robot_left(self, robot_id: RobotId) -> None:
        self.news.append(("left", robot_id))


async def spawn(mode: str, ns: str, endpoint: str, robot_id: RobotId) -> asyncio.subprocess.Process:
    """``python -m tests.zenoh_peer``, once its robot's token is declared."""
    peer = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "tests.zenoh_peer",
        mode,
        ns,
        endpoint,
        str(robot_id),
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    assert peer.stdout is not None
    try:
        line = await asyncio.wait_for(peer.stdout.readline(), 20)
    except BaseException:
        await stop(peer)
        raise
    if line != b"open\n":
        _, err = await stop(peer)
        raise AssertionError(f"the peer did not open: {line!r}\n{err.decode()}")
    return peer


async def stop(peer: asyncio.subprocess.Process) -> tuple[bytes, bytes]:
    """Kills ``peer`` if it still runs; what it wrote."""
    if peer.returncode is None:
        peer.kill()
    return await asyncio.wait_for(peer.communicate(), 20)


# -- 1. two robots in two sessions -------------------------------------------------------------


async def test_two_robots_in_two_sessions_meet_and_talk() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        a, b = recorders(2), recorders(2)
        async with robot(1, a, home) as robot_a, robot(2, b, away) as robot_b:
            assert home.zid
            assert away.zid
            assert home.zid != away.zid
            assert robot_a.address == ("zenoh", home.zid, 1)
            assert robot_b.address == ("zenoh", away.zid, 2)
            await until(lambda: a[0].knows(2) and b[0].knows(1), "the robots learn of each other")
            a[0].send(2, Note("hello", [1]))
            reply = await b[1].request(1, Query(21), timeout=5)
            assert isinstance(reply, Answer)
            assert (reply.value, reply.by_level, reply.robot_id) == (42, 1, 1)
            assert reply.msg_type == MsgType.ACCEPT
            await until(lambda: b[0].external, "the note arrives")
            assert texts(b[0]) == ["hello"]
            assert b[0].external[0].robot_id == 1
            assert [type(m) for m in a[1].external] == [Query]
            assert robot_a.dropped == robot_b.dropped == {}
        # Robot 1 sent the note and the answer, robot 2 the query: nothing else.
        assert (home.sent, home.received, away.sent, away.received) == (2, 1, 1, 2)
        assert home.dropped == away.dropped == {}
        assert away.session is None  # its last robot closed it
        assert home.session is not None  # started: open until closed


async def test_robots_of_one_process_talk_without_a_put() -> None:
    transport = ZenohTransport(namespace=namespace())
    a, b = recorders(2), recorders(2)
    b[0].expected = 1
    async with robot(1, a, transport), robot(2, b, transport) as robot_b:
        assert a[0].knows(2)
        assert b[0].knows(1)
        a[0].send(2, Note("next door", []))
        reply = await a[1].request(2, Query(4), timeout=5)
        await asyncio.wait_for(robot_b.run(), 5)
    assert (reply.value, reply.robot_id) == (8, 2)
    assert texts(b[0]) == ["next door"]
    assert (transport.sent, transport.received, transport.dropped) == (0, 0, {})


async def test_an_endpoint_refuses_unknown_robots_and_sending_once_closed() -> None:
    ns = namespace()
    transport = ZenohTransport(namespace=ns)
    watching, sink = Sink(), Sink()
    first = await transport.open(1, watching)
    try:
        first.follow_membership(True)
        assert first.address == ("zenoh", transport.zid, 1)
        with pytest.raises(
            UnknownRobotError, match=rf"robot 1: robot 2 is not on this Zenoh .*{ns}"
        ):
            first.send(2, b"nobody there")
        second = await transport.open(2, sink)
        assert watching.news == [("joined", 2)]  # news of this process's robots: at once
        assert list(first.peers()) == [2]
        assert first.knows(2)
        first.send(2, b"hi")
        await until(lambda: sink.received)
        assert sink.received == [(b"hi", 1)]
        second.close()
        assert watching.news == [("joined", 2), ("left", 2)]
        assert list(first.peers()) == []
        assert not first.knows(2)
    finally:
        first.close()
    with pytest.raises(RobotStateError, match="robot 1: Zenoh endpoint is closed"):
        first.send(1, b"too late")
    first.close()  # idempotent
    assert transport.session is None


async def test_a_robot_that_comes_and_goes_in_one_pass_is_news_once() -> None:
    # This session hears its own robots' tokens too: that echo must not announce again
    # a robot that open() and close() announced already.
    transport = ZenohTransport(namespace=namespace())
    watching = Sink()
    watcher = await transport.open(2, watching)
    try:
        watcher.follow_membership(True)
        (await transport.open(1, Sink())).close()  # before the loop drains anything
        watcher.send(2, b"after the echo")  # queued behind it
        await until(lambda: watching.received)
        assert watching.news == [("joined", 1), ("left", 1)]
        assert transport.members() == [2]
    finally:
        watcher.close()


# -- 2. membership -----------------------------------------------------------------------------


async def test_robots_joining_and_leaving_are_news_to_a_running_robot() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        watcher = Watcher()
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        b, c = recorders(2), recorders(2)
        async with robot(1, [watcher, Recorder()], home) as robot_a:
            async with robot(3, c, away):
                async with robot(2, b, away):
                    await until(lambda: watcher.knows(2) and watcher.knows(3), lambda: watcher.news)
                    assert sorted(home.members()) == sorted(away.members()) == [1, 2, 3]
                    watcher.broadcast(Note("to all", []))
                    await until(lambda: b[0].external and c[0].external, "the broadcast")
                # Robot 2 closed: its token went with it.
                assert 2 not in away.members()  # at once in its own process
                await until(lambda: ("left", 2) in watcher.news, lambda: watcher.news)
                assert not watcher.knows(2)
                assert watcher.knows(3)
                assert sorted(home.members()) == sorted(away.members()) == [1, 3]
                watcher.broadcast(Note("to who is left", []))  # to robot 3 only
                await until(lambda: len(c[0].external) == 2, "the second broadcast")
                assert away.session is not None  # robot 3 still uses it
            assert away.session is None  # robot 3 was the last one here
            await until(lambda: ("left", 3) in watcher.news, lambda: watcher.news)
            assert not watcher.knows(3)
            assert home.members() == [1]
            assert watcher.news == [("joined", 3), ("joined", 2), ("left", 2), ("left", 3)]
            assert texts(b[0]) == ["to all"]
            assert texts(c[0]) == ["to all", "to who is left"]
            assert robot_a.dropped == {}


async def test_a_robot_whose_process_is_killed_leaves_within_seconds() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        watcher = Watcher()
        async with robot(1, [watcher, Recorder()], home):
            peer = await spawn("linger", ns, endpoint, 5)
            try:
                await until(lambda: watcher.knows(5), "the peer's robot joins", timeout=20)
                asking = asyncio.ensure_future(watcher.request(5, Query(1), timeout=30))
                await asyncio.sleep(0.05)
                assert not asking.done()  # the peer answers nothing
                os.kill(peer.pid, signal.SIGKILL)
                await until(lambda: not watcher.knows(5), "the killed robot leaves")
                with pytest.raises(RobotGone, match="robot 5 left"):
                    await asyncio.wait_for(asking, 5)
                await until(lambda: ("left", 5) in watcher.news, lambda: watcher.news)
                assert 5 not in home.members()
            finally:
                _, err = await stop(peer)
            assert peer.returncode == -signal.SIGKILL, err.decode()


# -- 3. two OS processes -----------------------------------------------------------------------


async def test_two_robots_in_two_processes() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        stack = recorders(2)
        async with robot(1, stack, home) as robot_a:
            peer = await spawn("talk", ns, endpoint, 2)
            try:
                await until(lambda: stack[0].external, "the peer's greeting", timeout=20)
                hello = stack[0].external[0]
                assert isinstance(hello, Note)
                assert (hello.text, hello.hops, hello.robot_id) == (
                    "hello from another process",
                    [2],
                    2,
                )
                answer = await stack[0].request(2, Query(20), timeout=10)
                assert (answer.value, answer.robot_id) == (40, 2)
                stack[0].send(2, Note("bye", []))
                # The peer's robot stops, closes its session, and the process exits: an
                # unclosed session would keep it alive past the timeout.
                out, err = await asyncio.wait_for(peer.communicate(), 20)
            finally:
                await stop(peer)
            assert peer.returncode == 0, err.decode()
            assert out == b"closed\n", err.decode()
            assert b"Traceback" not in err, err.decode()
            await until(lambda: not stack[0].knows(2), "the peer's robot leaves")
            assert robot_a.dropped == {}


# -- 4. who sent a datagram -----------------------------------------------------------------


async def test_a_datagram_speaks_for_the_live_robot_its_key_names_only() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        a, b = recorders(2), recorders(2)
        async with robot(1, a, home) as robot_a, robot(2, b, away):
            await until(lambda: a[0].knows(2))
            to_robot_1 = f"{ns}/d/{home.zid}/1"
            async with stranger(endpoint) as session:
                await reachable(session, f"{to_robot_1}/99")
                publish(session, f"{to_robot_1}/99", datagram("nobody's", 99))  # no token: nobody
                publish(session, f"{to_robot_1}/2", datagram("robot 3's?", 3))  # robot 2's key
                await until(lambda: sum(robot_a.dropped.values()) >= 2, lambda: robot_a.dropped)
            b[0].send(1, Note("robot 2's", []))
            await until(lambda: a[0].external, "robot 2's own note")
            assert robot_a.dropped == {"unknown_source": 1, "spoofed_sender": 1}
            assert texts(a[0]) == ["robot 2's"]
            assert home.dropped == {}


async def test_what_a_robot_sends_as_soon_as_it_joins_is_its_own() -> None:
    # Its token and its datagram travel through different subscribers: the token must
    # be known when the datagram is, or the datagram speaks for nobody (unknown_source).
    ns = namespace()
    bursts, burst = 8, 100
    async with listener(ns) as (home, endpoint):
        a = recorders(2)
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        async with robot(1, a, home) as robot_a:
            try:
                anchor = await away.open(0, Sink())  # keeps the session open
                await until(lambda: anchor.knows(1))
                for first in range(2, 2 + bursts * burst, burst):
                    for robot_id in range(first, first + burst):  # without a pause
                        joining = await away.open(robot_id, Sink())
                        joining.send(1, datagram(str(robot_id), robot_id))
                    sent = first + burst - 2
                    await until(
                        lambda sent=sent: (
                            len(a[0].external) + sum(robot_a.dropped.values()) >= sent
                        ),
                        lambda: robot_a.dropped,
                    )
            finally:
                away.close()
            assert robot_a.dropped == {}
            assert sorted(int(text) for text in texts(a[0])) == list(range(2, 2 + bursts * burst))


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
async def test_what_a_robot_sends_just_before_it_leaves_is_its_own() -> None:
    # Zenoh withdraws a token ahead of the data still on its way: the last words of a
    # robot that leaves (its reply, its goodbye) must not arrive from nobody.
    ns = namespace()
    rounds = 5
    async with listener(ns) as (home, endpoint):
        a = recorders(2)
        async with robot(1, a, home) as robot_a:
            for robot_id in range(2, 2 + rounds):
                away = ZenohTransport(namespace=ns, connect=[endpoint])
                leaving = await away.open(robot_id, Sink())
                try:
                    await until(functools.partial(leaving.knows, 1))
                    leaving.send(1, datagram(f"last words of {robot_id}", robot_id))
                finally:
                    leaving.close()  # the session closes with it
                assert away.session is None
            await until(
                lambda: len(a[0].external) + sum(robot_a.dropped.values()) >= rounds,
                lambda: robot_a.dropped,
            )
            assert robot_a.dropped == {}
            assert len(texts(a[0])) == rounds


async def test_in_one_process_what_a_robot_sends_before_it_leaves_is_its_own() -> None:
    transport = ZenohTransport(namespace=namespace())
    sink = Sink()
    staying = await transport.open(2, sink)
    try:
        leaving = await transport.open(1, Sink())
        leaving.send(2, b"last words")
        leaving.close()  # before the loop delivers them
        await until(lambda: sink.received)
        assert sink.received == [(b"last words", 1)]
    finally:
        staying.close()


# -- 5. with a swarm key ---------------------------------------------------------------------


async def test_with_a_swarm_key_robots_talk_and_a_stranger_is_refused() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        signed_home = AuthenticatedTransport(home, KEY)
        signed_away = AuthenticatedTransport(ZenohTransport(namespace=ns, connect=[endpoint]), KEY)
        a, b = recorders(2), recorders(2)
        wire: list[bytes] = []  # what robot 2 puts for robot 1, as it travels
        tap = home.session.declare_subscriber(
            f"{ns}/d/{home.zid}/1/2", lambda sample: wire.append(sample.payload.to_bytes())
        )
        try:
            async with robot(1, a, signed_home) as robot_a, robot(2, b, signed_away) as robot_b:
                await until(lambda: a[0].knows(2) and b[0].knows(1))
                reply = await b[1].request(1, Query(21), timeout=5)
                assert (reply.value, reply.robot_id) == (42, 1)
                b[0].send(1, Note("signed", []))
                await until(lambda: a[0].external and len(wire) == 2, "the signed note")
                key = f"{ns}/d/{home.zid}/1/2"  # robot 2's, alive
                async with stranger(endpoint) as session:
                    await reachable(session, key)
                    for data in (
                        b"short",
                        datagram("unsigned, and long enough for a trailer", 2),
                        sign(datagram("signed with another key", 2), 2, 2**60, 1, OTHER_KEY),
                        wire[-1],  # robot 2's note, recorded and sent again
                    ):
                        publish(session, key, data)
                    await until(lambda: sum(robot_a.dropped.values()) >= 4, lambda: robot_a.dropped)
                assert robot_a.dropped == {
                    "transport.auth.too_short": 1,
                    "transport.auth.forged": 2,
                    "transport.auth.replay": 1,
                }
                assert texts(a[0]) == ["signed"]
                assert [type(m) for m in a[1].external] == [Query]
                assert robot_b.dropped == {}
                assert signed_home.stats["accepted"] == 2  # the query and the note
        finally:
            tap.undeclare()


# -- 6. listening beyond loopback ------------------------------------------------------------


async def test_listening_beyond_loopback_without_a_key_warns() -> None:
    transport = ZenohTransport(namespace=namespace(), listen=["tcp/0.0.0.0:0"])
    try:
        with pytest.warns(
            InsecureBindWarning,
            match=r"Zenoh session listens on tcp/0\.0\.0\.0:0 without authentication: .*"
            r"CAS_ASYNC_SWARM_KEY=<hex> or a key file.* AuthenticatedTransport",
        ):
            async with robot(1, recorders(1), transport):
                assert transport.session is not None
    finally:
        transport.close()
    assert transport.session is None


async def test_a_warning_made_an_error_opens_no_session() -> None:
    transport = ZenohTransport(namespace=namespace(), listen=["tcp/0.0.0.0:0"])
    with pytest.raises(InsecureBindWarning):  # pytest runs with warnings as errors
        await transport.open(1, Sink())
    assert transport.session is None
    assert transport.members() == []
    with pytest.warns(InsecureBindWarning):  # and the robot may be opened again
        endpoint = await transport.open(1, Sink())
    endpoint.close()
    assert transport.session is None


@pytest.mark.parametrize("case", ["key", "config", "loopback"])
async def test_no_warning_with_a_key_a_config_of_ones_own_or_on_loopback(case: str) -> None:
    zenoh_transport = {
        "key": lambda: ZenohTransport(namespace=namespace(), listen=["tcp/0.0.0.0:0"]),
        "config": lambda: ZenohTransport(
            namespace=namespace(), config=loopback_config(listen=["tcp/0.0.0.0:0"])
        ),
        "loopback": lambda: ZenohTransport(namespace=namespace(), listen=["tcp/127.0.0.1:0"]),
    }[case]()
    transport: Transport = (
        AuthenticatedTransport(zenoh_transport, KEY) if case == "key" else zenoh_transport
    )
    try:
        # Warnings are errors here: opening without one is the assertion.
        async with robot(1, recorders(1), transport):
            assert zenoh_transport.session is not None
    finally:
        zenoh_transport.close()


# -- 7. virtual time -----------------------------------------------------------------------


def test_virtual_time_is_refused_before_a_session_opens() -> None:
    transport = ZenohTransport(namespace=namespace())

    async def main() -> None:
        with pytest.raises(
            ConfigurationError,
            match=r"robot 1: ZenohTransport uses real sockets, which do not run on virtual "
            r"time; use MemoryTransport with VirtualClock, or ScaledClock",
        ):
            async with robot(1, recorders(1), transport, clock=VirtualClock()):
                pass

    cas_async.run(main(), virtual=True)
    assert transport.session is None
    assert not transport.supports_virtual_time
    assert not AuthenticatedTransport(
        ZenohTransport(namespace=namespace()), KEY
    ).supports_virtual_time


# -- 8. bad input ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "ns", ["a*b", "", "a//b", "/a", "a/", "a b", "a/**", "$a", "a?b", "a#b", "@/x", 7]
)
def test_a_namespace_that_is_no_key_prefix_is_refused(ns: Any) -> None:
    with pytest.raises(
        ConfigurationError, match=r"Zenoh namespace must be .*, got " + re.escape(repr(ns))
    ):
        ZenohTransport(namespace=ns)


def test_an_unknown_mode_is_refused() -> None:
    with pytest.raises(
        ConfigurationError, match="Zenoh mode must be peer, client or router, got 'server'"
    ):
        ZenohTransport(namespace=namespace(), mode="server")  # type: ignore[arg-type]


@pytest.mark.parametrize("robot_id", ["7", 1.5, True, None], ids=["str", "float", "bool", "none"])
async def test_a_robot_id_that_is_no_int_is_refused_before_a_session_opens(robot_id: Any) -> None:
    transport = ZenohTransport(namespace=namespace())
    with pytest.raises(
        ConfigurationError, match=rf"a Zenoh robot id must be an int, got {robot_id!r}"
    ):
        await transport.open(robot_id, Sink())
    assert transport.session is None


async def test_a_robot_id_is_attached_once() -> None:
    transport = ZenohTransport(namespace=namespace())
    sink = Sink()
    endpoint = await transport.open(1, sink)
    try:
        with pytest.raises(
            ConfigurationError, match="robot 1 is already attached to this ZenohTransport"
        ):
            await transport.open(1, Sink())
        endpoint.send(1, b"still mine")  # the first one is unharmed
        await until(lambda: sink.received)
        assert sink.received == [(b"still mine", 1)]
    finally:
        endpoint.close()
    assert transport.session is None


async def test_a_robot_id_alive_in_another_session_is_refused() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        first = await home.open(1, Sink())
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        try:
            other = await away.open(2, Sink())
            await until(lambda: other.knows(1))
            with pytest.raises(
                ConfigurationError,
                match=rf"robot 1 is already on the Zenoh swarm '{ns}' \(session {home.zid}\)",
            ):
                await away.open(1, Sink())
            assert sorted(away.members()) == [1, 2]
            assert away.zid_of(1) == home.zid
        finally:
            away.close()
            first.close()


async def test_a_refused_robot_leaves_no_session_open() -> None:
    # A session nobody uses keeps the process from exiting: the one opened for a robot
    # that is then refused must close again.
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        first = await home.open(1, Sink())
        refused = 0
        try:
            for _ in range(6):
                away = ZenohTransport(namespace=ns, connect=[endpoint])
                try:
                    endpoint_1 = await away.open(1, Sink())
                except ConfigurationError:
                    refused += 1
                    assert away.session is None
                else:  # robot 1's token came too late to refuse this one: it happens
                    endpoint_1.close()
                    assert away.session is None
        finally:
            first.close()
        assert refused  # usually all six: the session learns the tokens while it opens


async def test_datagrams_under_malformed_keys_are_counted_and_harm_nothing() -> None:
    ns = namespace()
    async with listener(ns) as (home, endpoint):
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        a, b, c = recorders(2), recorders(2), recorders(2)
        async with (
            robot(1, a, home) as robot_a,
            robot(2, b, home) as robot_b,
            robot(3, c, away),
        ):
            await until(lambda: a[0].knows(3))
            here = f"{ns}/d/{home.zid}"
            async with stranger(endpoint) as session:
                await reachable(session, f"{here}/1/3")
                for key in (
                    f"{here}/1/2/3",  # one level too many: not robot 2's, nor from robot 3
                    f"{here}/1",  # one too few
                    f"{here}/one/3",
                    f"{here}/1/three",
                    f"{here}/77/3",  # no robot 77 here
                ):
                    publish(session, key, datagram("stray", 3))
                await until(lambda: home.dropped.get("no_receiver"), lambda: home.dropped)
            c[0].send(1, Note("real", []))
            await until(lambda: a[0].external, "robot 3's note")
            assert home.dropped == {"bad_key": 2, "no_receiver": 1}
            assert texts(a[0]) == ["real"]
            assert b[0].external == []
            # A key that names no robots is a stranger's: counted by this process's first
            # robot too, so a run's results show it; a receiver gone is the transport's only.
            assert robot_a.dropped == {"transport.bad_key": 2}
            assert robot_b.dropped == {}


# -- 9. sessions and threads -------------------------------------------------------------------


async def test_the_last_robot_closes_the_session_and_the_next_opens_another() -> None:
    before = python_threads()
    transport = ZenohTransport(namespace=namespace())
    zids: list[str] = []
    counts: list[int] = []
    for _ in range(3):
        a, b = recorders(1), recorders(1)
        b[0].expected = 1
        async with robot(1, a, transport):
            async with robot(2, b, transport) as robot_b:
                zids.append(transport.zid)
                assert transport.session is not None
                a[0].send(2, Note("here", []))
                await asyncio.wait_for(robot_b.run(), 5)
            assert transport.session is not None  # robot 1 still uses it
        assert transport.session is None
        assert transport.zid == ""
        assert transport.members() == []
        await until(lambda: python_threads() <= before, lambda: threading.enumerate())
        counts.append(os_threads())
    assert len(set(zids)) == 3
    assert "" not in zids
    # Zenoh keeps a runtime for the process (one thread of slack for its pools), but
    # sessions leave no threads behind: a leak would grow by a thread or more per round.
    assert counts[-1] <= counts[0] + 1, counts


async def test_a_started_transport_keeps_its_session_until_closed() -> None:
    transport = ZenohTransport(namespace=namespace())
    async with transport:
        zid = transport.zid
        assert zid
        for _ in range(2):
            async with robot(1, recorders(1), transport):
                assert transport.zid == zid
            assert transport.session is not None
    assert transport.session is None


async def test_a_start_cancelled_while_the_session_opens_leaves_none_open() -> None:
    before = python_threads()
    transport = ZenohTransport(namespace=namespace())
    starting = asyncio.ensure_future(transport.start())
    await asyncio.sleep(0)  # the session is opening in a thread
    starting.cancel()
    with pytest.raises(asyncio.CancelledError):
        await starting
    assert transport.session is None
    async with robot(1, recorders(1), transport):  # and it opens again
        assert transport.session is not None
    assert transport.session is None
    await until(lambda: python_threads() <= before, lambda: threading.enumerate())


# -- 10. reliability -------------------------------------------------------------------------


async def test_five_thousand_messages_all_arrive_in_order() -> None:
    ns = namespace()
    count = 5_000
    async with listener(ns) as (home, endpoint):
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        a, b = recorders(1), recorders(1)
        b[0].expected = count
        async with robot(1, a, away) as robot_a, robot(2, b, home) as robot_b:
            await until(lambda: a[0].knows(2))
            for i in range(count):
                a[0].send(2, Note(PAYLOAD, [i]))
            await asyncio.wait_for(robot_b.run(), 30)
            assert [m.hops[0] for m in b[0].external if isinstance(m, Note)] == list(range(count))
            assert robot_a.dropped == robot_b.dropped == {}
        assert (away.sent, home.received) == (count, count)
        assert away.dropped == home.dropped == {}


async def test_a_burst_faster_than_the_link_waits_instead_of_dropping() -> None:
    # Raw endpoints put as fast as Python can: Zenoh's default (DROP) loses some of it.
    ns = namespace()
    count = 20_000
    async with listener(ns) as (home, endpoint):
        away = ZenohTransport(namespace=ns, connect=[endpoint])
        sink = Sink()
        receiver = await home.open(2, sink)
        try:
            sender = await away.open(1, Sink())
            await until(lambda: sender.knows(2))
            for i in range(count):
                sender.send(2, i.to_bytes(4, "big") * 256)
            await until(lambda: len(sink.received) >= count, lambda: len(sink.received), 20)
            assert [int.from_bytes(data[:4], "big") for data, _ in sink.received] == list(
                range(count)
            )
            assert {sender for _, sender in sink.received} == {1}
        finally:
            away.close()
            receiver.close()
        assert (away.sent, home.received) == (count, count)
