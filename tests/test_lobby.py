"""The lobby of a run across processes against strangers (issue 44 item 8).

* a stranger who answers a worker's hello first (garbage, or a well-formed but
  unsigned ``Refused``) cannot stop it joining: the world's signed welcome wins;
* a worker with another key than the world's is still told so within seconds;
* a flood of hellos that do not check costs the world a bounded number of signed
  refusals, the rest counted;
* a hello signed for one world is refused by another that uses the same key.

The first two on a real Zenoh router in this process (the world is its router, as
:class:`~cas_async.scenario._processes._world.World` is); the last two on a fake
session whose subscriptions the test feeds by hand, with a clock it moves.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any, Final

import pytest

from cas_async import ConfigurationError, SwarmKey
from cas_async.scenario import load_scenario
from cas_async.scenario._processes._control import WORLD, Channel, Hello, Refused, Welcome
from cas_async.scenario._processes._joining import join
from cas_async.scenario._processes._lobby import (
    REFUSAL_BURST,
    REFUSALS_PER_SECOND,
    Lobby,
    lobby_of,
)

zenoh = pytest.importorskip("zenoh")

ROOT: Final = Path(__file__).resolve().parents[1]
SCENARIO: Final = ROOT / "apps" / "fire_brigade" / "scenarios" / "thesis_5_8_2.toml"
KEY: Final = SwarmKey.generate()
LIMIT: Final = 20.0
"""Wall seconds a join may take here; only a broken lobby comes near."""


def _lobby(
    session: Any, key: SwarmKey | None, clock: Callable[[], float] = time.monotonic
) -> Lobby:
    joined: list[tuple[int, int]] = []
    return Lobby(
        session,
        key,
        load_scenario(SCENARIO, ["run.virtual=true", 'run.transport="memory"']),
        1,
        "cas_async/run/test",
        lambda: [[1, 2, 3]],
        lambda pid, index: joined.append((pid, index)),
        clock,
    )


# -- on a real router ------------------------------------------------------------------------


@pytest.fixture
async def world() -> AsyncIterator[tuple[Any, str]]:
    """A Zenoh router in this process (the world's session) and its endpoint."""
    from cas_async.transport.zenoh import loopback_config
    from tests.processes_support import free_endpoint

    endpoint = free_endpoint()
    session = await asyncio.to_thread(zenoh.open, loopback_config(mode="router", listen=[endpoint]))
    try:
        yield session, endpoint
    finally:
        session.close()


async def test_a_stranger_who_answers_first_cannot_stop_a_worker_joining(
    world: tuple[Any, str],
) -> None:
    session, endpoint = world
    from cas_async.transport.zenoh import loopback_config

    stranger = await asyncio.to_thread(
        zenoh.open, loopback_config(mode="client", listen=[], connect=[endpoint])
    )
    loop = asyncio.get_running_loop()
    prefix = lobby_of(str(session.zid()))
    answered: list[str] = []

    def answer(suffix: str, sender: int, message: Any) -> None:
        pass

    fake = Channel(stranger, prefix, WORLD, None, answer)  # unsigned: the stranger has no key

    def on_hello(sample: Any) -> None:  # on Zenoh's thread: answer at once, twice
        nonce = str(sample.key_expr).rsplit("/", 1)[1]
        if nonce not in answered:
            answered.append(nonce)
            stranger.put(f"{prefix}/ctl/welcome/{nonce}", b"\x00garbage")
            loop.call_soon_threadsafe(fake.send, f"welcome/{nonce}", Refused("go away"))

    subscriber = stranger.declare_subscriber(f"{prefix}/ctl/hello/*", on_hello)
    lobby: Lobby | None = None
    try:
        joining = asyncio.ensure_future(join(endpoint, KEY, LIMIT))
        await asyncio.sleep(0.3)  # the world's lobby opens late: the stranger is first
        assert answered, "the stranger saw the hello and answered it"
        lobby = _lobby(session, KEY)
        async with asyncio.timeout(LIMIT):
            welcome = await joining
    finally:
        if lobby is not None:
            lobby.close()
        subscriber.undeclare()
        fake.close()
        stranger.close()
    assert isinstance(welcome, Welcome)
    assert welcome.index == 0


async def test_a_worker_with_another_key_is_told_within_seconds(world: tuple[Any, str]) -> None:
    session, endpoint = world
    lobby = _lobby(session, KEY)
    began = time.monotonic()
    try:
        with pytest.raises(ConfigurationError, match="signs with another key than this worker's"):
            await join(endpoint, SwarmKey.generate(), LIMIT, refusal_grace=0.5)
    finally:
        lobby.close()
    assert time.monotonic() - began < 5.0  # the grace, and the world's answer


# -- on a fake session -----------------------------------------------------------------------


class _Payload:
    def __init__(self, data: bytes) -> None:
        self._data = data

    def to_bytes(self) -> bytes:
        return self._data


class _Sample:
    def __init__(self, key: str, data: bytes) -> None:
        self.key_expr = key
        self.payload = _Payload(data)


class FakeSession:
    """What a Channel asks of a Zenoh session: subscribe, put; the test delivers by hand."""

    def __init__(self, zid: str) -> None:
        self._zid = zid
        self.subscribers: list[tuple[str, Callable[[Any], None]]] = []
        self.puts: list[tuple[str, bytes]] = []

    def zid(self) -> str:
        return self._zid

    def declare_subscriber(self, key: str, callback: Callable[[Any], None]) -> Any:
        self.subscribers.append((key, callback))

        class Declared:
            def undeclare(self) -> None:
                pass

        return Declared()

    def put(self, key: str, payload: bytes, **kwargs: Any) -> None:
        self.puts.append((key, payload))

    def deliver(self, key: str, payload: bytes) -> None:
        for pattern, callback in self.subscribers:
            prefix = pattern.removesuffix("*")
            rest = key.removeprefix(prefix)
            if key == pattern or (
                pattern.endswith("*") and key.startswith(prefix) and "/" not in rest
            ):
                callback(_Sample(key, payload))


async def _settle() -> None:
    for _ in range(3):
        await asyncio.sleep(0)


async def test_a_flood_of_unsigned_hellos_gets_a_bounded_number_of_signed_refusals() -> None:
    now = [1000.0]
    session = FakeSession("aaaa")
    lobby = _lobby(session, KEY, lambda: now[0])
    hello = f"{lobby_of('aaaa')}/ctl/hello/"
    for n in range(1000):  # a thousand fake nonces at once
        session.deliver(f"{hello}{n:016x}", b"\x00not signed")
    await _settle()
    assert len(session.puts) == REFUSAL_BURST
    assert lobby.refused["control.unsigned"] == 1000
    assert lobby.refused["control.refusal_suppressed"] == 1000 - REFUSAL_BURST
    now[0] += 1.0  # a second later: the rate's worth more
    for n in range(1000, 2000):
        session.deliver(f"{hello}{n:016x}", b"\x00not signed")
    await _settle()
    assert len(session.puts) == REFUSAL_BURST + REFUSALS_PER_SECOND
    # A worker with the wrong key, saying hello four times a second, is still told:
    # once a second, whatever the flood.
    for _ in range(8):
        now[0] += 0.25
        session.deliver(f"{hello}{'f' * 16}", b"\x00not signed")
        await _settle()
    told = [key for key, _ in session.puts if key.endswith("f" * 16)]
    assert len(told) == 2
    lobby.close()


async def test_a_hello_signed_for_one_world_is_refused_by_another_with_the_same_key() -> None:
    first, second = FakeSession("aaaa"), FakeSession("bbbb")
    first_lobby, second_lobby = _lobby(first, KEY), _lobby(second, KEY)
    worker = FakeSession("cccc")
    nonce = "0123456789abcdef"
    signer = Channel(worker, lobby_of("aaaa"), 5, KEY, lambda *_: None)
    signer.send(f"hello/{nonce}", Hello(nonce, time.time(), 42))
    ((key, payload),) = worker.puts
    assert key == f"{lobby_of('aaaa')}/ctl/hello/{nonce}"
    first.deliver(key, payload)  # where it was made for: welcomed
    second.deliver(f"{lobby_of('bbbb')}/ctl/hello/{nonce}", payload)  # captured, put elsewhere
    await _settle()
    assert [k for k, _ in first.puts] == [f"{lobby_of('aaaa')}/ctl/welcome/{nonce}"]
    assert second_lobby.refused == {"control.unsigned": 1}
    welcomed = [k for k, data in second.puts if b"welcome" in data]
    assert welcomed == []  # at most the world's Refused went back, never a Welcome
    for closing in (first_lobby, second_lobby, signer):
        closing.close()
