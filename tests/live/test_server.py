"""The view's server as a browser and as a hostile client see it: HTTP, the handshake, RFC 6455.

Served here is a replay (``ReplayView``) of a finished run; the live view's
server is the same code.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import struct
from collections.abc import AsyncIterator
from pathlib import Path

import numpy as np
import pytest

from cas_async.live import ReplayView, decode_frame
from cas_async.live._connection import CSP

from .helpers import read_trace

websockets = pytest.importorskip("websockets")


@pytest.fixture
async def replay(fire_run: Path) -> AsyncIterator[ReplayView]:
    async with ReplayView(fire_run) as view:
        yield view


async def _request(view: ReplayView, head: str) -> tuple[int, dict[str, str], bytes]:
    reader, writer = await asyncio.open_connection("127.0.0.1", view.port)
    try:
        writer.write(head.encode("latin-1"))
        data = await asyncio.wait_for(reader.read(), 10)
    finally:
        writer.close()
        await writer.wait_closed()
    top, _, body = data.partition(b"\r\n\r\n")
    lines = top.decode("latin-1").split("\r\n")
    headers = {k.lower(): v.strip() for k, _, v in (line.partition(":") for line in lines[1:])}
    return int(lines[0].split()[1]), headers, body


def _get(path: str, port: int, extra: str = "") -> str:
    return f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n{extra}\r\n"


@pytest.mark.parametrize(
    ("path", "kind"),
    [("/", "text/html"), ("/view.js", "text/javascript"), ("/view.css", "text/css")],
)
async def test_the_page_is_self_contained_and_locked_down(
    replay: ReplayView, path: str, kind: str
) -> None:
    status, headers, body = await _request(replay, _get(path, replay.port))
    assert status == 200
    assert headers["content-type"].startswith(kind)
    assert headers["content-security-policy"] == CSP
    assert "default-src 'none'" in CSP
    assert headers["x-content-type-options"] == "nosniff"
    assert int(headers["content-length"]) == len(body)
    text = body.decode()
    for external in ("http://", "https://", "@import", "@font-face", "url("):
        assert external not in text, f"{path} reaches beyond its server: {external}"


@pytest.mark.parametrize(
    ("head", "status", "says"),
    [
        ("GET /nothing HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n", 404, b"not found"),
        ("POST / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n", 405, b"only GET"),
        ("GET / HTTP/1.1\r\nHost: rebound.example:{port}\r\n\r\n", 403, b"not this machine"),
        ("GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n", 426, b"WebSocket"),
        ("nonsense\r\n\r\n", 400, b"HTTP/1.x"),
        ("GET / HTTP/1.1\r\nX: " + "a" * 20000 + "\r\n\r\n", 431, b"too long"),
        (
            "GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
            "Connection: Upgrade\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Key: short\r\n\r\n",
            400,
            b"16 bytes",
        ),
        (
            "GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nOrigin: http://evil.example\r\n"
            "Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
            "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n",
            403,
            b"not this server's page",
        ),
    ],
    ids=[
        "unknown-path",
        "post",
        "foreign-host",
        "no-upgrade",
        "garbage",
        "huge",
        "bad-key",
        "origin",
    ],
)
async def test_requests_that_do_not_belong_are_refused(
    replay: ReplayView, head: str, status: int, says: bytes
) -> None:
    got, _, body = await _request(replay, head.replace("{port}", str(replay.port)))
    assert got == status
    assert says in body


async def test_a_replay_answers_each_seek_with_the_sample_at_or_before(
    replay: ReplayView, fire_run: Path
) -> None:
    trace = read_trace(fire_run / "trace.csv")
    async with websockets.connect(f"ws://127.0.0.1:{replay.port}/ws", max_size=None) as socket:
        hello = json.loads(await socket.recv())
        assert hello["mode"] == "replay"
        assert hello["times"] == trace.times
        assert {event["type"] for event in hello["events"]} == {"exchange", "delivered"}
        first = decode_frame(await socket.recv())
        assert first.seq == 0
        await socket.send("not json")  # ignored: the connection stays
        await socket.send(json.dumps({"type": "seek"}))  # no t: ignored too
        for t in (12.5, 3.0, 1e9, -5.0):
            await socket.send(json.dumps({"type": "seek", "t": t}))
            frame = decode_frame(await socket.recv())
            k = max(0, max((i for i, at in enumerate(trace.times) if at <= t), default=0))
            assert frame.t == trace.times[k]
            assert np.array_equal(frame.xy, trace.xy[k])
            assert np.array_equal(frame.carrying, trace.carrying[k])
        assert frame.final is False  # -5: the first sample
        await socket.send(json.dumps({"type": "seek", "t": 1e9}))
        assert decode_frame(await socket.recv()).final is True


async def _open(view: ReplayView) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    reader, writer = await asyncio.open_connection("127.0.0.1", view.port)
    key = base64.b64encode(os.urandom(16)).decode()
    writer.write(
        (
            f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{view.port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    await reader.readuntil(b"\r\n\r\n")
    return reader, writer


async def _next_frame(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    first, second = await reader.readexactly(2)
    length = second & 0x7F
    if length == 126:
        (length,) = struct.unpack("!H", await reader.readexactly(2))
    elif length == 127:
        (length,) = struct.unpack("!Q", await reader.readexactly(8))
    return first & 0x0F, await reader.readexactly(length)


def _client_frame(opcode: int, payload: bytes, *, masked: bool = True, fin: bool = True) -> bytes:
    head = bytes([(0x80 if fin else 0) | opcode])
    n = len(payload)
    size = (
        bytes([n])
        if n < 126
        else bytes([126]) + struct.pack("!H", n)
        if n < 65536
        else (bytes([127]) + struct.pack("!Q", n))
    )
    if not masked:
        return head + size + payload
    mask = os.urandom(4)
    size = bytes([size[0] | 0x80]) + size[1:]
    return head + size + mask + bytes(b ^ mask[k % 4] for k, b in enumerate(payload))


@pytest.mark.parametrize(
    ("frame", "code"),
    [
        (_client_frame(1, b"{}", masked=False), 1002),
        (bytes([0x81 | 0x40, 0x80]) + b"\0\0\0\0", 1002),  # RSV1 set
        (_client_frame(3, b"x"), 1002),  # an unknown opcode
        (_client_frame(0, b"x"), 1002),  # a continuation of nothing
        (_client_frame(9, b"x" * 126), 1002),  # a control frame too long
        (_client_frame(1, b"\xff\xfe"), 1007),
        (_client_frame(2, b"\x00"), 1003),
        (_client_frame(1, b"a" * 70000), 1009),
    ],
    ids=["unmasked", "rsv", "opcode", "continuation", "long-ping", "utf8", "binary", "too-big"],
)
async def test_a_client_that_breaks_the_protocol_is_closed_with_the_rfc_code(
    replay: ReplayView, frame: bytes, code: int
) -> None:
    reader, writer = await _open(replay)
    try:
        assert (await _next_frame(reader))[0] == 1  # the hello
        assert (await _next_frame(reader))[0] == 2  # the first frame
        writer.write(frame)
        opcode, payload = await asyncio.wait_for(_next_frame(reader), 10)
        assert opcode == 8
        assert struct.unpack("!H", payload[:2])[0] == code
        assert await asyncio.wait_for(reader.read(), 10) == b""  # then the server hangs up
    finally:
        writer.close()


async def test_a_ping_is_answered_and_fragments_are_joined(replay: ReplayView) -> None:
    reader, writer = await _open(replay)
    try:
        await _next_frame(reader)
        await _next_frame(reader)
        writer.write(_client_frame(9, b"hi"))
        assert await _next_frame(reader) == (10, b"hi")
        seek = json.dumps({"type": "seek", "t": 5.0}).encode()
        writer.write(_client_frame(1, seek[:5], fin=False))
        writer.write(_client_frame(9, b"in between"))  # a control frame may come inside
        writer.write(_client_frame(0, seek[5:]))
        assert await _next_frame(reader) == (10, b"in between")
        opcode, payload = await _next_frame(reader)
        assert opcode == 2
        assert decode_frame(payload).t == 5.0
        writer.write(_client_frame(8, struct.pack("!H", 1000)))
        opcode, payload = await _next_frame(reader)
        assert (opcode, payload) == (8, struct.pack("!H", 1000))
    finally:
        writer.close()
