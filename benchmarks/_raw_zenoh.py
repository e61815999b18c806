"""Hand-written asyncio on raw Zenoh: the baselines of ``bench_zenoh``.

What a user would write without cas_async, minimal and fair: two sessions (one
listening on loopback TCP, the other connecting to it; multicast scouting off), one
publisher per direction declared with ``CongestionControl.BLOCK`` (what
``ZenohTransport`` puts with), and one plain-callback subscriber per session whose
callback only appends the payload to a deque and wakes the loop once per batch (the
best hand-off LIMITS.md found: ``call_soon_threadsafe`` per sample is slower). The
payloads are the framework's bytes (``raw_sample`` / ``raw_ack`` packed by
``raw_pack``), unpacked on the loop.

Throughput (:class:`RawSender`, :class:`RawReceiver`): ``bench_external``'s credit
window, at most ``WINDOW`` unacknowledged, an ack every ``ACK_EVERY`` (and one for the
last message when asked, as across processes). Round trip (:class:`RawAsker`,
:class:`RawAnswerer`): the asker publishes and awaits a future that its drain
resolves; the answerer's drain puts each request on an ``asyncio.Queue`` read by a
task that publishes the reply (as ``bench_external``'s raw answerer).

Before anything is timed each side waits until its publisher matches the other's
subscriber (Zenoh drops a put that no subscriber it knows of matches). Every session
is closed on every way out: a process with a callback subscriber's session open never
exits.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import os
import socket
import time
from collections import deque
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import asynccontextmanager
from typing import Any

from ._common import COUNT_AT, ID_AT, LOOPBACK, N_AT, raw_ack, raw_pack, raw_sample, raw_unpack
from .bench_external import ACK_EVERY, RECEIVER, SENDER, WINDOW

__all__ = [
    "KNOW_LIMIT",
    "PORT_ATTEMPTS",
    "RawAnswerer",
    "RawAsker",
    "RawReceiver",
    "RawSender",
    "free_port",
    "fresh_namespace",
    "matched",
    "open_session",
    "raw_key",
    "raw_listening",
    "raw_session",
]

KNOW_LIMIT = 10.0  # seconds for two sides to see each other (tokens, or matching)
PORT_ATTEMPTS = 5  # a port picked free may be taken before the session listens on it
_namespaces = itertools.count()


def fresh_namespace() -> str:
    """A namespace no other measurement (of this process or another) uses."""
    return f"bench/p{os.getpid()}/n{next(_namespaces)}"


def free_port() -> int:
    """A TCP port on loopback that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((LOOPBACK, 0))
        return int(sock.getsockname()[1])


def raw_key(namespace: str, robot: int) -> str:
    """The key the raw baselines publish datagrams for ``robot`` under."""
    return f"{namespace}/raw/{robot}"


async def open_session(listen: Sequence[str] = (), connect: Sequence[str] = ()) -> Any:
    """Opens a ``zenoh.Session`` (peer, no scouting); the caller closes it."""
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    config.insert_json5("scouting/multicast/enabled", "false")
    return await asyncio.to_thread(zenoh.open, config)


@asynccontextmanager
async def raw_session(connect: str) -> AsyncIterator[Any]:
    """A raw session connecting to ``connect``, closed when the block ends."""
    session = await open_session(connect=[connect])
    try:
        yield session
    finally:
        session.close()


@asynccontextmanager
async def raw_listening() -> AsyncIterator[tuple[Any, str]]:
    """A raw session listening on a free loopback TCP port, and its endpoint.

    The session is closed when the block ends, however it ends.
    """
    for attempt in range(PORT_ATTEMPTS):
        endpoint = f"tcp/{LOOPBACK}:{free_port()}"
        try:
            session = await open_session(listen=[endpoint])
        except Exception:  # zenoh.ZError: the port was taken meanwhile
            if attempt == PORT_ATTEMPTS - 1:
                raise
            continue
        break
    try:
        yield session, endpoint
    finally:
        session.close()


def publisher(session: Any, namespace: str, robot: int) -> Any:
    """A publisher of datagrams for ``robot``, blocking (never dropping) when queues are full."""
    import zenoh

    return session.declare_publisher(
        raw_key(namespace, robot), congestion_control=zenoh.CongestionControl.BLOCK
    )


def subscribe(session: Any, namespace: str, robot: int, handle: Callable[[bytes], None]) -> Any:
    """Hands every payload for ``robot`` to ``handle`` on the running loop, in order.

    The callback runs on the subscriber's Zenoh thread: it appends to a deque and
    schedules one drain of the loop while none is pending.
    """
    loop = asyncio.get_running_loop()
    queue: deque[bytes] = deque()
    scheduled = False

    def drain() -> None:
        nonlocal scheduled
        scheduled = False
        for _ in range(len(queue)):
            handle(queue.popleft())

    def callback(sample: Any) -> None:
        nonlocal scheduled
        queue.append(sample.payload.to_bytes())
        if not scheduled:
            scheduled = True
            loop.call_soon_threadsafe(drain)

    return session.declare_subscriber(raw_key(namespace, robot), callback)


async def matched(*publishers: Any) -> None:
    """Waits until every publisher has a matching subscriber.

    Raises:
        RuntimeError: not within ``KNOW_LIMIT`` seconds.
    """
    deadline = time.monotonic() + KNOW_LIMIT
    while not all(p.matching_status.matching for p in publishers):
        if time.monotonic() > deadline:
            raise RuntimeError(f"raw Zenoh publishers found no subscriber within {KNOW_LIMIT} s")
        await asyncio.sleep(0.001)


# -- throughput -----------------------------------------------------------------------


class RawSender:
    """Publishes ``raw_sample``s, at most ``WINDOW`` ahead of the acks it received."""

    def __init__(self, session: Any, namespace: str, total: int) -> None:
        self.total = total
        self.sent = 0
        self.acked = 0
        self.started = 0.0
        self.publisher = publisher(session, namespace, RECEIVER)
        self.last_ack: asyncio.Future[float] = asyncio.get_running_loop().create_future()
        subscribe(session, namespace, SENDER, self.received)

    def top_up(self) -> None:
        """Publishes what the window allows (the first call starts the clock)."""
        if not self.started:
            self.started = time.perf_counter()
        n, limit = self.sent, min(self.total, self.acked + WINDOW)
        put = self.publisher.put
        while n < limit:
            put(raw_pack(raw_sample(n, SENDER)))
            n += 1
        self.sent = n

    def received(self, data: bytes) -> None:
        self.acked = raw_unpack(data)[COUNT_AT]  # type: ignore[assignment]
        if self.acked >= self.total and not self.last_ack.done():
            self.last_ack.set_result(time.perf_counter())
        self.top_up()


class RawReceiver:
    """Counts ``raw_sample``s and acknowledges every ``ACK_EVERY`` (and the last if asked)."""

    def __init__(self, session: Any, namespace: str, total: int, *, ack_last: bool) -> None:
        self.total = total
        self.count = 0
        self.ack_last = ack_last
        self.publisher = publisher(session, namespace, SENDER)
        self.done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
        subscribe(session, namespace, RECEIVER, self.received)

    def received(self, data: bytes) -> None:
        raw_unpack(data)
        self.count = count = self.count + 1
        if count % ACK_EVERY == 0 or (count == self.total and self.ack_last):
            self.publisher.put(raw_pack(raw_ack(count, RECEIVER)))
        if count == self.total:
            self.done.set_result(time.perf_counter())


# -- round trip -----------------------------------------------------------------------


class RawAsker:
    """Publishes a request and awaits the future its subscriber's drain resolves."""

    def __init__(self, session: Any, namespace: str) -> None:
        self.publisher = publisher(session, namespace, RECEIVER)
        self.waiter: asyncio.Future[list[Any]] | None = None
        subscribe(session, namespace, SENDER, self.received)

    def received(self, data: bytes) -> None:
        reply = raw_unpack(data)
        waiter, self.waiter = self.waiter, None
        if waiter is not None and not waiter.done():
            waiter.set_result(reply)

    async def latencies(self, count: int) -> list[float]:
        """Seconds each of ``count`` round trips took, in order."""
        loop = asyncio.get_running_loop()
        put = self.publisher.put
        latencies = []
        for n in range(count):
            t = time.perf_counter()
            waiter = self.waiter = loop.create_future()
            put(raw_pack(raw_sample(n, SENDER)))
            await waiter
            latencies.append(time.perf_counter() - t)
        return latencies


class RawAnswerer:
    """Queues each request for a task that publishes the reply; counts what it answered."""

    def __init__(self, session: Any, namespace: str) -> None:
        self.publisher = publisher(session, namespace, SENDER)
        self.inbox: asyncio.Queue[list[Any]] = asyncio.Queue()
        self.count = 0
        subscribe(session, namespace, RECEIVER, self.received)
        self.task = asyncio.get_running_loop().create_task(self.answer())

    def received(self, data: bytes) -> None:
        self.inbox.put_nowait(raw_unpack(data))

    async def answer(self) -> None:
        put = self.publisher.put
        while True:
            request = await self.inbox.get()
            put(raw_pack(raw_sample(request[N_AT], RECEIVER, request[ID_AT])))
            self.count += 1

    async def stop(self) -> None:
        """Cancels the answering task and waits for it."""
        self.task.cancel()
        await asyncio.gather(self.task, return_exceptions=True)
