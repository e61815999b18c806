"""What the Zenoh tests share: namespaces, bounded waits, sessions on loopback, a sink.

Every test opens its own sessions under its own namespace (so no test sees another's
robots), closes them before it ends, and waits for the network only with a bound.
Sessions that must be reached listen on ``tcp/127.0.0.1:0`` with the admin space on:
the admin space is the one place a session says which port the OS gave it.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import threading
import uuid
from collections.abc import AsyncIterator, Callable
from typing import Any

import pytest

from cas_async import Layer, Robot, RobotId, Transport, ZenohTransport
from cas_async.transport import Codec
from cas_async.transport.zenoh._transport import loopback_config
from tests.stacks import STACK_MESSAGES, Note, Recorder

zenoh = pytest.importorskip("zenoh")

CODEC = Codec.for_stack(2, STACK_MESSAGES)
"""What a robot of two ``tests.stacks`` layers reads: to craft datagrams it accepts."""


def namespace() -> str:
    """A namespace no other test uses."""
    return f"cas_test/{uuid.uuid4().hex}"


async def until(
    condition: Callable[[], object], what: str | Callable[[], object] = "", timeout: float = 5.0
) -> None:
    """Polls while real datagrams travel; fails (saying ``what``) after ``timeout`` s."""
    try:
        async with asyncio.timeout(timeout):
            while not condition():
                await asyncio.sleep(0.002)
    except TimeoutError:
        said = what() if callable(what) else what
        raise AssertionError(f"not within {timeout} s: {said}") from None


def admin_config(**kwargs: Any) -> Any:
    """:func:`loopback_config` with the admin space on, where the session tells its locators."""
    config = loopback_config(**kwargs)
    config.insert_json5("adminspace/enabled", "true")
    return config


def locators(session: Any) -> list[str]:
    """Where ``session`` listens, the OS-picked ports included (blocking: run in a thread)."""
    for reply in session.get(f"@/{session.zid()}/*", timeout=5.0):
        with contextlib.suppress(Exception):  # error replies, non-JSON entries (link state)
            info = json.loads(reply.ok.payload.to_string())
            if isinstance(info, dict) and "locators" in info:
                return list(info["locators"])
    raise AssertionError("the admin space does not say where the session listens")


@contextlib.asynccontextmanager
async def listener(ns: str) -> AsyncIterator[tuple[ZenohTransport, str]]:
    """A started transport listening on a loopback port the OS picked, and that endpoint."""
    transport = ZenohTransport(namespace=ns, config=admin_config())
    try:
        await transport.start()
        (endpoint,) = await asyncio.to_thread(locators, transport.session)
        assert endpoint.startswith("tcp/127.0.0.1:")
        assert not endpoint.endswith(":0")
        yield transport, endpoint
    finally:
        transport.close()


@contextlib.asynccontextmanager
async def stranger(endpoint: str) -> AsyncIterator[Any]:
    """A raw Zenoh session, no robot's, connected to ``endpoint``."""
    session = await asyncio.to_thread(zenoh.open, loopback_config(connect=[endpoint]))
    try:
        yield session
    finally:
        session.close()


async def reachable(session: Any, key: str) -> None:
    """Waits until a subscriber hears what ``session`` puts under ``key``."""
    publisher = session.declare_publisher(key)
    try:
        await until(lambda: publisher.matching_status.matching, f"nobody subscribes to {key}")
    finally:
        publisher.undeclare()


def publish(session: Any, key: str, data: bytes) -> None:
    session.put(key, data, congestion_control=zenoh.CongestionControl.BLOCK)


def datagram(text: str, claimed: RobotId, msg_id: int = 1) -> bytes:
    """A Note a robot of the test stack decodes, its header claiming robot ``claimed``."""
    note = Note(text, [])
    note.msg_id, note.robot_id = msg_id, claimed
    return CODEC.encode(note)


def texts(layer: Recorder) -> list[str]:
    return [msg.text for msg in layer.external if isinstance(msg, Note)]


def robot(robot_id: RobotId, layers: list[Layer], transport: Transport, **kwargs: Any) -> Robot:
    return Robot(robot_id, layers, transport=transport, messages=STACK_MESSAGES, **kwargs)


class Sink:
    """A DatagramSink that keeps everything it is told."""

    def __init__(self) -> None:
        self.received: list[tuple[bytes, RobotId | None]] = []
        self.dropped: list[str] = []
        self.news: list[tuple[str, RobotId]] = []

    def datagram_received(self, data: bytes, sender: RobotId | None = None) -> None:
        self.received.append((data, sender))

    def transport_dropped(self, reason: str, detail: str) -> None:
        self.dropped.append(reason)

    def robot_joined(self, robot_id: RobotId) -> None:
        self.news.append(("joined", robot_id))

    def robot_left(self, robot_id: RobotId) -> None:
        self.news.append(("left", robot_id))


def python_threads() -> int:
    """Python threads but the loop's executor's (``asyncio.to_thread`` keeps idle ones)."""
    return sum(1 for thread in threading.enumerate() if not thread.name.startswith("asyncio"))


def os_threads() -> int:
    """Threads of this process, Zenoh's own included (Linux)."""
    return len(os.listdir("/proc/self/task"))
