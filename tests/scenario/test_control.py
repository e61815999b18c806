"""The control plane of a run across processes: typed, signed messages; what is refused, counted.

Channels talk through a real Zenoh session on this machine only (no port is
opened: a session delivers what it publishes to its own subscribers too).
"""

from __future__ import annotations

import asyncio
import hashlib
import hmac
from collections.abc import AsyncIterator, Callable, Iterator
from typing import Any

import msgspec
import pytest

from cas_async import SwarmKey
from cas_async._time._deliveries import ITEM
from cas_async.scenario._processes._control import (
    WORLD,
    Beat,
    Bye,
    Channel,
    Control,
    Counts,
    Failed,
    Full,
    Go,
    Grant,
    Hello,
    Ready,
    Remote,
    Stop,
    Welcome,
    Window,
)
from cas_async.scenario._processes._observer import MotionRecord, Observation

zenoh = pytest.importorskip("zenoh")
from cas_async.transport.zenoh._transport import loopback_config  # noqa: E402
from tests.zenoh_support import namespace, until  # noqa: E402

KEY = SwarmKey(bytes(range(32)))
Heard = list[tuple[str, int, Control]]


# -- channels -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def session() -> Iterator[Any]:
    opened = zenoh.open(loopback_config(listen=[]))
    yield opened
    opened.close()


class Run:
    """Channels of one run (its own namespace), closed by the fixture; raw puts beside them."""

    def __init__(self, session: Any) -> None:
        self.session = session
        self.ns = namespace()
        self.channels: list[Channel] = []

    def channel(
        self,
        sender: int,
        key: SwarmKey | None = None,
        *,
        fail_on: Callable[[Control], bool] = lambda _message: False,
        run: str | None = None,
    ) -> tuple[Channel, Heard]:
        """A channel speaking as ``sender``; what it hears (its handler raises on ``fail_on``)."""
        heard: Heard = []

        def handle(suffix: str, sender: int, message: Control) -> None:
            if fail_on(message):
                raise RuntimeError(f"cannot apply {message!r}")
            heard.append((suffix, sender, message))

        channel = Channel(self.session, self.ns if run is None else run, sender, key, handle)
        self.channels.append(channel)
        return channel, heard

    def put(self, suffix: str, payload: bytes) -> None:
        """Publishes raw bytes where the run's channels listen (as a stranger could)."""
        self.session.put(f"{self.ns}/ctl/{suffix}", payload)

    def envelope(
        self,
        suffix: str,
        message: Control,
        *,
        sender: int = 0,
        count: int = 1,
        run: str | None = None,
        key: SwarmKey | None = None,
    ) -> bytes:
        """The bytes a channel sends, as the module docs describe them: envelope, then tag."""
        body = msgspec.msgpack.encode(message)
        payload = msgspec.msgpack.encode([self.ns if run is None else run, sender, count, body])
        if key is not None:
            signed = f"{self.ns}/ctl/{suffix}".encode() + b"\0" + payload
            payload += hmac.new(key.secret, signed, hashlib.sha256).digest()[:16]
        return payload


@pytest.fixture
async def run(session: Any) -> AsyncIterator[Run]:
    made = Run(session)
    yield made
    for channel in made.channels:
        channel.close()


async def heard_all(heard: Heard, count: int, channel: Channel) -> None:
    await until(
        lambda: len(heard) + sum(channel.refused.values()) >= count,
        lambda: f"heard {heard}, refused {channel.refused}",
    )


MESSAGES: list[Control] = [
    Hello("nonce-1", 12.5, 4242),
    Welcome(0, "cas_async/run/ab", "s.toml", {"run": {"seed": 3}}, [[1, 2], [3]]),
    Full(2),
    Ready(),
    Go(1.7e9),
    Window(
        4,
        2.25,
        Observation([MotionRecord(1.0, 3, 1, [0.0] * 10)]),
        [Remote(2.5, ITEM, 1, 2, 3, item=7, sent=2.0, reach=0.5, refused="too far")],
        Counts({"a.B": 1}, {"c.D": 2}, {"decode": 1}, {"control.replayed": 1}),
        stopped_at=12.5,
    ),
    Grant(5),
    Beat(),
    Stop(),
    Failed("worker 1: boom"),
    Bye(Counts(), waited=0.75, waited_grant=0.25),
]


@pytest.mark.parametrize("key", [None, KEY], ids=["unsigned", "signed"])
async def test_every_message_round_trips_with_its_suffix_and_sender(
    run: Run, key: SwarmKey | None
) -> None:
    world, _ = run.channel(WORLD, key)
    worker, heard = run.channel(1, key)
    worker.listen("to/1/**")
    for message in MESSAGES:
        world.send("to/1/news", message)
    await heard_all(heard, len(MESSAGES), worker)
    assert heard == [("to/1/news", WORLD, message) for message in MESSAGES]
    assert worker.refused == {}


async def test_a_channel_hears_only_what_it_listens_to(run: Run) -> None:
    world, _ = run.channel(WORLD)
    worker, heard = run.channel(0)
    worker.listen("w/0")
    world.send("w/1", Grant(1))  # another worker's
    world.send("w/0", Grant(2))
    await heard_all(heard, 1, worker)
    await asyncio.sleep(0.05)
    assert heard == [("w/0", WORLD, Grant(2))]


async def test_a_message_of_another_run_is_refused(run: Run) -> None:
    worker, heard = run.channel(0, KEY)
    worker.listen("**")
    run.put("w", run.envelope("w", Grant(1), run="cas_async/run/other", key=KEY))
    run.put("w", run.envelope("w", Grant(2), count=2, key=KEY))
    await heard_all(heard, 2, worker)
    assert heard == [("w", 0, Grant(2))]
    assert worker.refused == {"control.other_run": 1}


async def test_a_bad_or_missing_tag_is_refused_when_a_key_is_set(run: Run) -> None:
    worker, heard = run.channel(0, KEY)
    worker.listen("**")
    stranger, _ = run.channel(5, SwarmKey(bytes(range(1, 33))))
    unkeyed, _ = run.channel(6)
    stranger.send("w", Grant(1))  # signed with another key
    unkeyed.send("w", Grant(2))  # no tag at all
    run.put("w", b"short")  # not even a tag's length
    forged = bytearray(run.envelope("w", Grant(3), sender=7, key=KEY))
    forged[5] ^= 1  # a bit flipped after signing
    run.put("w", bytes(forged))
    run.put("w", run.envelope("w", Grant(4), sender=7, key=KEY))
    await heard_all(heard, 5, worker)
    assert heard == [("w", 7, Grant(4))]
    assert worker.refused == {"control.unsigned": 4}


async def test_a_replay_is_refused_each_senders_count_must_grow(run: Run) -> None:
    worker, heard = run.channel(0, KEY)
    worker.listen("**")
    for count in (1, 3, 3, 2, 4):  # a repeat, then an old one
        run.put("w", run.envelope("w", Grant(count), sender=2, count=count, key=KEY))
    run.put("w", run.envelope("w", Grant(1), sender=3, count=1, key=KEY))  # its own count
    await heard_all(heard, 6, worker)
    assert [(sender, message) for _, sender, message in heard] == [
        (2, Grant(1)),
        (2, Grant(3)),
        (2, Grant(4)),
        (3, Grant(1)),
    ]
    assert worker.refused == {"control.replayed": 2}


@pytest.mark.parametrize("key", [None, KEY], ids=["unsigned", "signed"])
async def test_malformed_bytes_are_refused_and_counted(run: Run, key: SwarmKey | None) -> None:
    worker, heard = run.channel(0, key)
    worker.listen("**")
    garbage = [
        b"\xc1 not msgpack at all",
        msgspec.msgpack.encode(["a run", 1]),  # an envelope too short
        msgspec.msgpack.encode([run.ns, 1, 1, b"\x92\x01"]),  # a body that is no message
        msgspec.msgpack.encode([run.ns, 1, 1, msgspec.msgpack.encode({"type": "nope"})]),
    ]
    for payload in garbage:
        if key is not None:  # signed, so that only its content is wrong
            signed = f"{run.ns}/ctl/w".encode() + b"\0" + payload
            payload += hmac.new(key.secret, signed, hashlib.sha256).digest()[:16]
        run.put("w", payload)
    run.put("w", run.envelope("w", Stop(), count=2, key=key))
    await heard_all(heard, 5, worker)
    assert heard == [("w", 0, Stop())]
    assert worker.refused == {"control.malformed": 4}


async def test_a_message_its_handler_cannot_apply_is_counted_and_the_rest_goes_on(
    run: Run,
) -> None:
    world, _ = run.channel(WORLD)
    worker, heard = run.channel(0, fail_on=lambda message: message == Grant(2))
    worker.listen("**")
    for k in (1, 2, 3):
        world.send("w", Grant(k))
    await heard_all(heard, 3, worker)
    assert [message for _, _, message in heard] == [Grant(1), Grant(3)]
    assert worker.refused == {"control.unusable": 1}


async def test_a_closed_channel_hears_no_more(run: Run) -> None:
    world, _ = run.channel(WORLD)
    worker, heard = run.channel(0)
    worker.listen("**")
    world.send("w", Grant(1))
    await heard_all(heard, 1, worker)
    worker.close()
    worker.close()  # idempotent
    world.send("w", Grant(2))
    listener, also = run.channel(1)
    listener.listen("**")
    world.send("w", Grant(3))
    await heard_all(also, 1, listener)  # by then Grant(2) would have come too
    assert heard == [("w", WORLD, Grant(1))]
