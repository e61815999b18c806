"""The view's server as a production server: every loop, time-outs, a cap, one Host, bounded JSON.

A bare :class:`ViewServer` (its hello is ``{"type":"hello"}``) on the test's loop,
with a clock the test moves: the sweeps that a thread runs every second in real
use are called by hand here, so no test waits for real time to pass.
"""

from __future__ import annotations

import asyncio
import base64
import json
import logging
import os
import socket
import struct
from collections.abc import AsyncIterator, Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest

from cas_async import VirtualTimeLoop, wall_bounded
from cas_async.live import ReplayView, ServerLimits, decode_frame
from cas_async.live._server import ViewServer
from cas_async.live._viewer import Viewer

HELLO = '{"type":"hello"}'
LIMIT = 10.0
"""Wall seconds any read here may take; only a broken server comes near."""


class FakeClock:
    """A wall clock that moves when the test says."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


class Hosted:
    """A bare server on the running loop, and what its viewers sent."""

    def __init__(self, limits: ServerLimits, clock: FakeClock) -> None:
        self.clock = clock
        self.messages: list[dict[str, Any]] = []
        self.server = ViewServer(self._opened, self._message, limits=limits, clock=clock)
        self.fail_on: str | None = None

    def _opened(self, viewer: Viewer) -> None:
        viewer.send_text(HELLO)

    def _message(self, viewer: Viewer, message: dict[str, Any]) -> None:
        if message.get("type") == self.fail_on:
            raise KeyError("a bug in the handler")
        self.messages.append(message)

    def sweep_after(self, seconds: float) -> None:
        self.clock.now += seconds
        self.server.sweep()


_QUIET = ServerLimits(request_timeout=10.0, idle_timeout=20.0, max_connections=3, tick=3600.0)
"""Sweeps by hand only: the ticker's thread waits an hour."""


@pytest.fixture
async def hosted() -> AsyncIterator[Hosted]:
    host = Hosted(_QUIET, FakeClock())
    await host.server.start("127.0.0.1", 0)
    try:
        yield host
    finally:
        host.server.close()


async def _connect(port: int) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    return await asyncio.open_connection("127.0.0.1", port)


async def _within(aw: Coroutine[Any, Any, Any]) -> Any:
    """``aw``, within :data:`LIMIT` wall seconds (on a virtual loop, loop time races on)."""
    task = asyncio.ensure_future(aw)
    if await wall_bounded(asyncio.shield(task), LIMIT) is None and not task.done():
        task.cancel()
        raise AssertionError(f"nothing within {LIMIT} s")
    return task.result()


async def _answer(reader: asyncio.StreamReader) -> bytes:
    answer: bytes = await _within(reader.read())
    return answer


def _handshake(port: int, extra: str = "") -> bytes:
    key = base64.b64encode(os.urandom(16)).decode()
    return (
        f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
        f"{extra}\r\n"
    ).encode()


async def _viewer(port: int) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    reader, writer = await _connect(port)
    writer.write(_handshake(port))
    head = await _within(reader.readuntil(b"\r\n\r\n"))
    assert head.startswith(b"HTTP/1.1 101 "), head
    return reader, writer


async def _frame(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    first, second = await _within(reader.readexactly(2))
    length = second & 0x7F
    if length == 126:
        (length,) = struct.unpack("!H", await reader.readexactly(2))
    elif length == 127:
        (length,) = struct.unpack("!Q", await reader.readexactly(8))
    return first & 0x0F, await reader.readexactly(length)


def _masked(opcode: int, payload: bytes) -> bytes:
    n = len(payload)
    size = bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + struct.pack("!H", n)
    if n >= 1 << 16:
        size = bytes([0x80 | 127]) + struct.pack("!Q", n)
    mask = os.urandom(4)
    body = bytes(b ^ mask[k % 4] for k, b in enumerate(payload))
    return bytes([0x80 | opcode]) + size + mask + body


def _close_code(payload: bytes) -> int:
    code: int = struct.unpack("!H", payload[:2])[0]
    return code


# -- every loop the project runs on ------------------------------------------------------


def _uvloop() -> asyncio.AbstractEventLoop:
    uvloop = pytest.importorskip("uvloop")
    loop: asyncio.AbstractEventLoop = uvloop.new_event_loop()
    return loop


LOOPS: dict[str, Callable[[], asyncio.AbstractEventLoop]] = {
    "asyncio": asyncio.new_event_loop,
    "uvloop": _uvloop,
    "virtual": VirtualTimeLoop,
}


def _on(loop_name: str, main: Callable[[], Coroutine[Any, Any, None]]) -> None:
    loop = LOOPS[loop_name]()
    try:
        loop.run_until_complete(main())
    finally:
        loop.close()


@pytest.mark.parametrize("loop_name", list(LOOPS))
def test_the_page_and_a_viewer_are_served_on_every_loop(loop_name: str) -> None:
    """uvloop's transport is no ``asyncio.Transport``: ``run --live`` on scaled time used it."""

    async def main() -> None:
        host = Hosted(ServerLimits(tick=3600.0), FakeClock())
        await host.server.start("127.0.0.1", 0)
        try:
            reader, writer = await _connect(host.server.port)
            writer.write(f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{host.server.port}\r\n\r\n".encode())
            assert (await _answer(reader)).startswith(b"HTTP/1.1 200 OK")
            writer.close()
            await writer.wait_closed()
            reader, writer = await _viewer(host.server.port)
            assert await _frame(reader) == (1, HELLO.encode())
            writer.close()
            await writer.wait_closed()
        finally:
            host.server.close()
            await asyncio.sleep(0)  # the server's transports see their end

    _on(loop_name, main)


# -- time-outs ---------------------------------------------------------------------------


async def test_a_connection_that_sends_no_request_is_answered_408_after_the_timeout(
    hosted: Hosted,
) -> None:
    reader, writer = await _connect(hosted.server.port)
    writer.write(b"GET / HTTP/1.1\r\nHost: 127.")  # and nothing more
    await asyncio.sleep(0.05)  # real time: the bytes reach the server
    hosted.sweep_after(9.0)
    assert hosted.server.connections == 1  # not yet
    hosted.sweep_after(1.5)
    answer = await _answer(reader)
    assert answer.startswith(b"HTTP/1.1 408 Request Timeout")
    writer.close()


async def test_a_silent_viewer_is_pinged_then_closed_and_one_that_answers_stays(
    hosted: Hosted,
) -> None:
    silent, silent_writer = await _viewer(hosted.server.port)
    lively, lively_writer = await _viewer(hosted.server.port)
    for reader in (silent, lively):
        assert await _frame(reader) == (1, HELLO.encode())
    hosted.sweep_after(10.5)  # past half the idle time-out: both pinged
    for reader in (silent, lively):
        assert await _frame(reader) == (0x9, b"")
    lively_writer.write(_masked(0xA, b""))  # the pong a browser sends by itself
    await asyncio.sleep(0.05)
    hosted.sweep_after(10.0)  # 20.5 s: the silent one goes
    opcode, payload = await _frame(silent)
    assert (opcode, _close_code(payload)) == (0x8, 1001)
    assert payload[2:] == b"idle"
    assert await _answer(silent) == b""
    hosted.sweep_after(15.0)
    assert len(hosted.server.viewers) == 1  # the one that answered
    for writer in (silent_writer, lively_writer):
        writer.close()


async def test_past_the_cap_a_connection_is_answered_503_and_counted(hosted: Hosted) -> None:
    viewers = [await _viewer(hosted.server.port) for _ in range(3)]  # the cap is 3
    reader, writer = await _connect(hosted.server.port)
    answer = await _answer(reader)
    assert answer.startswith(b"HTTP/1.1 503 Service Unavailable")
    assert b"Retry-After: 5" in answer
    assert hosted.server.refused["busy"] == 1
    writer.close()
    viewers[0][1].close()  # one leaves: a new one is served
    for _ in range(100):
        if len(hosted.server.viewers) < 3:
            break
        await asyncio.sleep(0.01)
    reader, writer = await _viewer(hosted.server.port)
    assert await _frame(reader) == (1, HELLO.encode())
    for _, other in [*viewers, (reader, writer)]:
        other.close()


# -- what a request may hold -------------------------------------------------------------


@pytest.mark.parametrize(
    "headers",
    [
        "Host: evil.example\r\nHost: 127.0.0.1:{port}\r\n",
        "Host: 127.0.0.1:{port}\r\nHost: evil.example\r\n",
        "Host: 127.0.0.1:{port}\r\nOrigin: http://127.0.0.1:{port}\r\nOrigin: http://evil\r\n",
    ],
    ids=["foreign-first", "foreign-last", "two-origins"],
)
async def test_a_repeated_host_or_origin_is_refused_400(hosted: Hosted, headers: str) -> None:
    reader, writer = await _connect(hosted.server.port)
    head = f"GET / HTTP/1.1\r\n{headers}\r\n".replace("{port}", str(hosted.server.port))
    writer.write(head.encode())
    answer = await _answer(reader)
    assert answer.startswith(b"HTTP/1.1 400 Bad Request"), answer[:40]
    assert b"a repeated " in answer
    writer.close()


# -- what a viewer may send --------------------------------------------------------------


@pytest.mark.parametrize(
    ("message", "code"),
    [
        (b"[" * 30_000 + b"]" * 30_000, 1009),  # 60 KB: past the size limit
        (b"[" * 2_000 + b"]" * 2_000, 1008),  # 4 KB, 2,000 deep: past the depth limit
        (b'{"type": "seek", "t": ' + b"[" * 9 + b"]" * 9 + b"}", 1008),
    ],
    ids=["30000-deep", "2000-deep", "10-deep"],
)
async def test_a_message_too_big_or_too_deep_gets_a_close_frame_and_no_traceback(
    hosted: Hosted, message: bytes, code: int, caplog: pytest.LogCaptureFixture
) -> None:
    reader, writer = await _viewer(hosted.server.port)
    await _frame(reader)
    writer.write(_masked(0x1, message))
    opcode, payload = await _frame(reader)
    assert (opcode, _close_code(payload)) == (0x8, code)
    writer.close()
    other, other_writer = await _viewer(hosted.server.port)  # the server goes on
    assert await _frame(other) == (1, HELLO.encode())
    other_writer.close()
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert hosted.messages == []


async def test_a_handler_that_fails_closes_that_viewer_with_1011_and_one_line(
    hosted: Hosted, caplog: pytest.LogCaptureFixture
) -> None:
    hosted.fail_on = "boom"
    reader, writer = await _viewer(hosted.server.port)
    await _frame(reader)
    writer.write(_masked(0x1, b'{"type": "boom"}'))
    opcode, payload = await _frame(reader)
    assert (opcode, _close_code(payload)) == (0x8, 1011)
    writer.close()
    (record,) = [r for r in caplog.records if r.name == "cas_async.live"]
    assert "KeyError" in record.getMessage()
    assert record.exc_info is None  # one line, no traceback


async def test_a_seek_to_an_integer_past_a_float_is_the_last_sample(fire_run: Path) -> None:
    async with ReplayView(fire_run) as view:
        reader, writer = await _viewer(view.port)
        hello = json.loads((await _frame(reader))[1])
        await _frame(reader)  # the first sample
        for t, index in ((b"9" * 400, -1), (b"-" + b"9" * 400, 0), (b"1e999", -1)):
            writer.write(_masked(0x1, b'{"type": "seek", "t": ' + t + b"}"))
            opcode, payload = await _frame(reader)
            assert opcode == 2
            assert decode_frame(payload).t == hello["times"][index]
        writer.close()


# -- out of file descriptors -------------------------------------------------------------


class _Exhausted:
    """A listening socket whose accepts fail with EMFILE until told otherwise."""

    def __init__(self) -> None:
        self.real = socket.create_server(("127.0.0.1", 0))
        self.client = socket.create_connection(self.real.getsockname())  # it stays readable
        self.accepts = 0
        self.exhausted = True

    def setblocking(self, flag: bool) -> None:
        self.real.setblocking(flag)

    def fileno(self) -> int:
        return self.real.fileno()

    def getsockname(self) -> Any:
        return self.real.getsockname()

    def accept(self) -> tuple[socket.socket, Any]:
        self.accepts += 1
        if self.exhausted:
            raise OSError(24, "Too many open files")
        return self.real.accept()

    def close(self) -> None:
        self.client.close()
        self.real.close()


@pytest.mark.parametrize("loop_name", ["asyncio", "virtual"])
def test_out_of_descriptors_the_acceptor_backs_off_on_the_wall_clock_with_one_line(
    loop_name: str, caplog: pytest.LogCaptureFixture
) -> None:
    """asyncio's own server wrote a traceback per accept, and spun on virtual time."""
    from cas_async.live._acceptor import Acceptor

    async def main() -> None:
        clock, sock, taken = FakeClock(), _Exhausted(), []
        acceptor = Acceptor(sock, taken.append, clock, backoff=1.0)  # type: ignore[arg-type]
        try:
            for _ in range(50):  # the socket stays readable: the loop would call again
                await asyncio.sleep(0)
            assert sock.accepts == 1  # one try, then the socket is not watched
            for _ in range(20):  # 20 s out of descriptors: one try a second
                clock.now += 1.0
                acceptor.tick(clock.now)
                await asyncio.sleep(0)
            assert sock.accepts == 21
            assert acceptor.exhausted == 21
            sock.exhausted = False
            clock.now += 1.0
            acceptor.tick(clock.now)
            for _ in range(5):
                await asyncio.sleep(0)
            assert len(taken) == 1
        finally:
            acceptor.close()
            for connection in taken:
                connection.close()

    with caplog.at_level(logging.WARNING, logger="cas_async.live"):
        _on(loop_name, main)
    lines = [r.getMessage() for r in caplog.records if r.name == "cas_async.live"]
    assert len(lines) == 2, lines  # the episode's start and its end
    assert "out of file descriptors" in lines[0]
    assert "accepting connections again" in lines[1]
    assert "21 accepts failed" in lines[1]
    assert all(r.exc_info is None for r in caplog.records)


@pytest.mark.slow  # about 20 s: an idle time-out, a burst, then a run
@pytest.mark.timeout(180)
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads CPU time from /proc")
def test_a_burst_past_the_open_file_limit_costs_a_line_and_no_core() -> None:
    """``run --live --live-wait`` on virtual time, its open files limited to 64 (setrlimit)."""
    pytest.importorskip("websockets")
    from benchmarks.live_fds import measure

    figures = measure("virtual", limit=64, idle=20, burst=150, hold=2.0)
    assert figures["idle_closed"] == 20  # 408 after the request time-out
    assert figures["tracebacks"] == 0
    assert figures["stderr_bytes"] <= 64 * 1024
    assert figures["cpu_share"] <= 0.5
    assert figures["viewer_answered"], figures
    assert figures["run_exit"] == 0
