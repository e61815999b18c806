"""The control plane's channel over a real Zenoh router: what it takes, what it refuses.

A router session and a client session on loopback in this process, as the world and a
worker have: the worker's channel sends under two keys the world reads
(``ctl/world`` and ``ctl/win/0``), as a worker does (its windows, then its ``Bye``).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Any

import pytest

from cas_async import SwarmKey
from cas_async.scenario._processes._control import WORLD, Beat, Channel, Control, Ready
from cas_async.transport.zenoh._sessions import loopback_config
from tests.processes_support import free_endpoint

zenoh = pytest.importorskip("zenoh")

KEY = SwarmKey(b"k" * 32)


@dataclass
class Taken:
    """What a channel's handler was given, in order."""

    messages: list[tuple[str, int, str]] = field(default_factory=list)

    def __call__(self, suffix: str, sender: int, message: Control) -> None:
        self.messages.append((suffix, sender, type(message).__name__))


@dataclass
class Link:
    router: Any
    client: Any


@pytest.fixture
async def link() -> AsyncIterator[Link]:
    endpoint = free_endpoint()
    router = await asyncio.to_thread(zenoh.open, loopback_config(mode="router", listen=[endpoint]))
    try:
        client = await asyncio.to_thread(
            zenoh.open, loopback_config(mode="client", listen=[], connect=[endpoint])
        )
        try:
            yield Link(router, client)
        finally:
            client.close()
    finally:
        router.close()


async def _until(condition: Any, limit: float = 20.0) -> None:
    deadline = time.monotonic() + limit
    while not condition() and time.monotonic() < deadline:
        await asyncio.sleep(0.02)


async def _connected(world: Channel, worker: Channel, taken: Taken) -> None:
    """Waits until the world's subscriptions reach the worker (a probe gets through)."""
    deadline = time.monotonic() + 20.0
    while not taken.messages and time.monotonic() < deadline:
        worker.send("world", Beat())
        await asyncio.sleep(0.1)
    assert taken.messages, "the world never heard the worker"


async def test_a_signed_message_of_the_run_is_taken_and_a_replay_refused(link: Link) -> None:
    taken = Taken()
    world = Channel(link.router, "ns", WORLD, KEY, taken)
    world.listen("world")
    worker = Channel(link.client, "ns", 0, KEY, lambda *_: None)
    try:
        await _connected(world, worker, taken)
        stranger = Channel(link.client, "ns", 0, SwarmKey(b"x" * 32), lambda *_: None)
        stranger.send("world", Ready())  # the wrong key
        link.client.put("ns/ctl/world", b"garbage")
        await _until(lambda: sum(world.refused.values()) >= 2)
        assert world.refused == {"control.unsigned": 2}
        # Count 1 again, from the same sender: a replay.
        Channel(link.client, "ns", 0, KEY, lambda *_: None).send("world", Ready())
        await _until(lambda: "control.replayed" in world.refused)
        assert world.refused == {"control.unsigned": 2, "control.replayed": 1}
        assert {sender for _, sender, _ in taken.messages} == {0}
    finally:
        world.close()


async def test_a_handler_that_raises_is_counted_and_the_rest_goes_on(link: Link) -> None:
    taken = Taken()

    def handle(suffix: str, sender: int, message: Control) -> None:
        if isinstance(message, Ready):
            raise ValueError("cannot apply it")
        taken(suffix, sender, message)

    world = Channel(link.router, "ns", WORLD, KEY, handle)
    world.listen("world")
    worker = Channel(link.client, "ns", 0, KEY, lambda *_: None)
    try:
        await _connected(world, worker, taken)
        before = len(taken.messages)
        for _ in range(5):
            worker.send("world", Ready())
            worker.send("world", Beat())
        await _until(lambda: len(taken.messages) >= before + 5)
        assert len(taken.messages) == before + 5
        assert world.refused == {"control.unusable": 5}
    finally:
        world.close()


async def test_messages_of_one_sender_under_two_keys_are_all_taken(link: Link) -> None:
    taken = Taken()
    world = Channel(link.router, "ns", WORLD, KEY, taken)
    world.listen("world")
    world.listen("win/*")
    worker = Channel(link.client, "ns", 0, KEY, lambda *_: None)
    try:
        await _connected(world, worker, taken)
        before = len(taken.messages)
        sent = 20_000
        for n in range(sent):
            worker.send("world" if n % 2 else "win/0", Beat())
            if n % 100 == 0:
                await asyncio.sleep(0)  # the loop drains meanwhile, as a worker's does
        await _until(lambda: len(taken.messages) + sum(world.refused.values()) >= before + sent)
        assert world.refused == {}
        assert len(taken.messages) == before + sent
    finally:
        world.close()
