"""One port for a view: the page over HTTP, and its WebSocket, on the caller's event loop.

``GET /`` serves the page, ``GET /view.js`` and ``GET /view.css`` its script and
style (nothing else: no CDN, no font), each with a Content-Security-Policy that
lets the page load only these and talk only to this server. ``GET /ws`` with a
WebSocket handshake opens a :class:`Viewer`. One request per HTTP connection.

A viewer never slows the sender: frames go out while the connection's buffer is
below its high-water mark; past it (a viewer that reads slowly, or not at all)
each new frame replaces the one waiting, and only the latest is sent when the
buffer drains (latest frame wins). Text messages (events) wait in a bounded
queue, the oldest dropped first and counted. Nothing here arms a timer, so the
server runs on a virtual-time loop as on any other.

Requests are checked as a page's server should be: the ``Host`` of a loopback
server must be a loopback name (a page of another site cannot reach it by DNS
rebinding), and a WebSocket handshake that comes from a page must come from
this server's own page (``Origin``).
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import socket
from collections import deque
from collections.abc import Callable
from importlib.resources import files
from typing import Final, final

from ._websocket import (
    CloseCode,
    FrameReader,
    Opcode,
    ProtocolError,
    accept_key,
    close_payload,
    frame,
)

__all__ = ["ViewServer", "Viewer", "is_loopback"]

REQUEST_LIMIT: Final = 16 * 1024
"""Bytes of an HTTP request head; a longer one is refused (431)."""
MESSAGE_LIMIT: Final = 64 * 1024
"""Bytes of a viewer's message (the page sends a few dozen)."""
HIGH_WATER: Final = 256 * 1024
"""Bytes a viewer's connection may buffer before frames are held back."""
TEXT_QUEUE: Final = 256
"""Text messages held for a viewer that cannot take them now; older ones are dropped."""
CSP: Final = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
)
_ASSETS: Final = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/view.js": ("view.js", "text/javascript; charset=utf-8"),
    "/view.css": ("view.css", "text/css; charset=utf-8"),
}
_REASONS: Final = {
    200: "OK",
    400: "Bad Request",
    403: "Forbidden",
    404: "Not Found",
    405: "Method Not Allowed",
    426: "Upgrade Required",
    431: "Request Header Fields Too Large",
}


def is_loopback(host: str) -> bool:
    """Whether ``host`` (an address or ``localhost``) names this machine only."""
    if host.strip("[]").lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def _load_assets() -> dict[str, tuple[bytes, str]]:
    page = files("cas_async.live").joinpath("page")
    return {
        path: (page.joinpath(name).read_bytes(), kind) for path, (name, kind) in _ASSETS.items()
    }


@final
class Viewer:
    """One open WebSocket: what the server sends to one page (or any client)."""

    def __init__(self, transport: asyncio.Transport, server: ViewServer) -> None:
        self._transport = transport
        self._server = server
        self._paused = False
        self._latest: bytes | None = None  # a frame held back while paused
        self._texts: deque[bytes] = deque()
        self.skipped_frames = 0
        """Frames replaced by a later one before they could be sent."""
        self.dropped_texts = 0
        """Text messages dropped from a full queue."""
        self.sent_frames = 0
        self.closed = False

    def send_frame(self, data: bytes) -> None:
        """Sends a binary frame now, or holds it back in place of the one held (see module docs)."""
        if self.closed:
            return
        if self._paused:
            if self._latest is not None:
                self.skipped_frames += 1
            self._latest = frame(Opcode.BINARY, data)
            return
        self._transport.write(frame(Opcode.BINARY, data))
        self.sent_frames += 1

    def send_text(self, text: str) -> None:
        """Sends a text message now, or queues it (bounded) behind the others."""
        if self.closed:
            return
        data = frame(Opcode.TEXT, text.encode("utf-8"))
        if not self._paused and not self._texts:
            self._transport.write(data)
            return
        if len(self._texts) >= TEXT_QUEUE:
            self._texts.popleft()
            self.dropped_texts += 1
        self._texts.append(data)

    def close(self, code: CloseCode = CloseCode.GOING_AWAY, reason: str = "") -> None:
        """Sends what waits and a close frame, then closes; a stalled viewer is cut at once."""
        if self.closed:
            return
        if self._paused:
            self.closed = True
            self._transport.abort()  # it reads nothing: what is buffered would never go
            return
        self._flush()
        self.closed = True
        self._transport.write(frame(Opcode.CLOSE, close_payload(code, reason)))
        self._transport.close()  # after the buffer is written: FIN, not a reset

    def fail(self, code: CloseCode, reason: str) -> None:
        """The client broke the protocol: a close frame, then the end of what we send.

        The connection is half-closed: what the client still sends is read and
        dropped until it closes its side, so that the close frame reaches it (closing
        with unread data would reset the connection, and could lose it).
        """
        self.closed = True
        self._transport.write(frame(Opcode.CLOSE, close_payload(code, reason)))
        if self._transport.can_write_eof():
            self._transport.write_eof()
        else:
            self._transport.close()

    @property
    def paused(self) -> bool:
        """Whether the connection's buffer is past its high-water mark (frames held back)."""
        return self._paused

    def pause(self) -> None:
        """The transport's buffer is full: hold frames back."""
        self._paused = True

    def resume(self) -> None:
        """The buffer drained: send what was held (texts first, then the latest frame)."""
        self._paused = False
        self._flush()

    def _flush(self) -> None:
        while self._texts and not self._paused:
            self._transport.write(self._texts.popleft())
        if self._latest is not None and not self._paused:
            latest, self._latest = self._latest, None
            self._transport.write(latest)
            self.sent_frames += 1

    def control(self, opcode: Opcode, payload: bytes) -> None:
        """Writes a control frame (a pong, a close): tiny, so even past the high-water mark."""
        if not self.closed:
            self._transport.write(frame(opcode, payload))


class _Connection(asyncio.Protocol):
    """One TCP connection: an HTTP request, then perhaps a WebSocket."""

    def __init__(self, server: ViewServer) -> None:
        self._server = server
        self._transport: asyncio.Transport | None = None
        self._head = bytearray()
        self._viewer: Viewer | None = None
        self._reader = FrameReader(MESSAGE_LIMIT)
        self._draining = False  # after a protocol error: read, drop, until the client closes

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        transport.set_write_buffer_limits(high=HIGH_WATER)

    def data_received(self, data: bytes) -> None:
        if self._draining:
            return
        if self._viewer is not None:
            self._websocket_data(self._viewer, data)
            return
        self._head += data
        end = self._head.find(b"\r\n\r\n")
        if end < 0:
            if len(self._head) > REQUEST_LIMIT:
                self._respond(431, b"request head too long\n")
            return
        if end > REQUEST_LIMIT:
            self._respond(431, b"request head too long\n")
            return
        rest = bytes(self._head[end + 4 :])
        self._request(bytes(self._head[:end]).decode("latin-1"))
        if self._viewer is not None and rest:
            self._websocket_data(self._viewer, rest)

    def _request(self, head: str) -> None:
        lines = head.split("\r\n")
        parts = lines[0].split(" ")
        if len(parts) != 3 or not parts[2].startswith("HTTP/1."):
            self._respond(400, b"not an HTTP/1.x request\n")
            return
        method, target, _ = parts
        headers: dict[str, str] = {}
        for line in lines[1:]:
            name, colon, value = line.partition(":")
            if not colon:
                self._respond(400, b"a header line without a colon\n")
                return
            headers[name.strip().lower()] = value.strip()
        path = target.partition("?")[0]
        problem = self._server.refuse(headers)
        if problem is not None:
            self._respond(403, problem.encode() + b"\n")
        elif method != "GET":
            self._respond(405, b"only GET\n", extra={"Allow": "GET"})
        elif path == "/ws":
            self._upgrade(headers)
        elif path in self._server.assets:
            body, kind = self._server.assets[path]
            self._respond(200, body, kind)
        else:
            self._respond(404, b"not found\n")

    def _upgrade(self, headers: dict[str, str]) -> None:
        transport = self._transport
        assert transport is not None
        if (
            "websocket" not in headers.get("upgrade", "").lower()
            or headers.get("sec-websocket-version") != "13"
        ):
            self._respond(426, b"a WebSocket (version 13) handshake is expected here\n",
                          extra={"Sec-WebSocket-Version": "13"})  # fmt: skip
            return
        try:
            accept = accept_key(headers.get("sec-websocket-key", ""))
        except ValueError as exc:
            self._respond(400, f"{exc}\n".encode())
            return
        transport.write(
            (
                "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                f"Sec-WebSocket-Accept: {accept}\r\n\r\n"
            ).encode("ascii")
        )
        self._viewer = viewer = Viewer(transport, self._server)
        self._server.opened(viewer)

    def _websocket_data(self, viewer: Viewer, data: bytes) -> None:
        try:
            messages = self._reader.feed(data)
        except ProtocolError as error:
            self._draining = True
            viewer.fail(error.code, error.reason)
            return
        for message in messages:
            if message.opcode is Opcode.PING:
                viewer.control(Opcode.PONG, message.payload)
            elif message.opcode is Opcode.CLOSE:
                code = message.payload[:2] if len(message.payload) >= 2 else b""
                viewer.control(Opcode.CLOSE, code)
                viewer.closed = True
                if self._transport is not None:
                    self._transport.close()
                return
            elif message.opcode is Opcode.TEXT:
                self._server.received(viewer, message.payload.decode("utf-8"))
            elif message.opcode is Opcode.BINARY:
                self._draining = True
                viewer.fail(CloseCode.UNSUPPORTED, "this server reads text messages only")
                return

    def _respond(
        self, status: int, body: bytes, kind: str = "text/plain; charset=utf-8",
        extra: dict[str, str] | None = None,
    ) -> None:  # fmt: skip
        transport = self._transport
        if transport is None or transport.is_closing():
            return
        headers = {
            "Content-Type": kind,
            "Content-Length": str(len(body)),
            "Cache-Control": "no-store",
            "Connection": "close",
            "X-Content-Type-Options": "nosniff",
            "Referrer-Policy": "no-referrer",
            "Cross-Origin-Resource-Policy": "same-origin",
            "Content-Security-Policy": CSP,
            **(extra or {}),
        }
        head = f"HTTP/1.1 {status} {_REASONS[status]}\r\n" + "".join(
            f"{name}: {value}\r\n" for name, value in headers.items()
        )
        transport.write(head.encode("latin-1") + b"\r\n" + body)
        transport.close()

    def eof_received(self) -> bool | None:
        return None  # the client is done: close (after what is buffered is written)

    def pause_writing(self) -> None:
        if self._viewer is not None:
            self._viewer.pause()

    def resume_writing(self) -> None:
        if self._viewer is not None:
            self._viewer.resume()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._viewer is not None:
            self._viewer.closed = True
            self._server.lost(self._viewer)


@final
class ViewServer:
    """The page and its WebSockets on one port (see the module docs).

    Args:
        on_open: called with each new viewer (send it the hello there).
        on_text: called with each text message a viewer sends.
    """

    def __init__(
        self,
        on_open: Callable[[Viewer], None],
        on_text: Callable[[Viewer, str], None] | None = None,
    ) -> None:
        self._on_open = on_open
        self._on_text = on_text
        self.assets = _load_assets()
        self.viewers: list[Viewer] = []
        """The open viewers."""
        self._server: asyncio.Server | None = None
        self._loopback = True
        self.host = ""
        self.port = 0
        self.connected = asyncio.Event()
        """Set once a viewer has opened its WebSocket."""
        self._lost = asyncio.Event()

    async def start(self, host: str, port: int, sock: socket.socket | None = None) -> None:
        """Listens on ``host``, ``port`` (0: a free one; :attr:`port` says which), or on ``sock``.

        Raises:
            OSError: the address cannot be bound.
        """
        loop = asyncio.get_running_loop()
        if sock is not None:
            self._server = await loop.create_server(lambda: _Connection(self), sock=sock)
        else:
            self._server = await loop.create_server(
                lambda: _Connection(self), host.strip("[]"), port, reuse_address=True
            )
        address = self._server.sockets[0].getsockname()
        self.host, self.port = (address[0] if sock is not None else host), address[1]
        self._loopback = is_loopback(self.host)

    @property
    def url(self) -> str:
        """The page's address."""
        host = self.host.strip("[]")
        shown = f"[{host}]" if ":" in host else host
        if host in ("", "0.0.0.0", "::"):
            shown = "127.0.0.1"
        return f"http://{shown}:{self.port}/"

    def refuse(self, headers: dict[str, str]) -> str | None:
        """Why a request is refused (a foreign ``Host`` or ``Origin``), or ``None``."""
        host = headers.get("host", "")
        name = host.rpartition(":")[0] if host.rpartition(":")[2].isdigit() else host
        if self._loopback and not is_loopback(name):
            return (
                f"Host {host!r:.60} is not this machine: a loopback server answers loopback names"
            )
        origin = headers.get("origin")
        if origin is not None and origin != f"http://{host}":
            return f"Origin {origin!r:.60} is not this server's page"
        return None

    def opened(self, viewer: Viewer) -> None:
        """A viewer completed its handshake."""
        self.viewers.append(viewer)
        self.connected.set()
        self._on_open(viewer)

    def received(self, viewer: Viewer, text: str) -> None:
        """A viewer sent a text message."""
        if self._on_text is not None:
            self._on_text(viewer, text)

    def lost(self, viewer: Viewer) -> None:
        """A viewer's connection is gone."""
        with contextlib.suppress(ValueError):
            self.viewers.remove(viewer)
        if not self.viewers:
            self._lost.set()

    def broadcast_frame(self, data: bytes) -> None:
        """Sends a frame to every viewer (held back for the slow ones)."""
        for viewer in self.viewers:
            viewer.send_frame(data)

    def broadcast_text(self, text: str) -> None:
        """Sends a text message to every viewer."""
        for viewer in self.viewers:
            viewer.send_text(text)

    def close(self, code: CloseCode = CloseCode.GOING_AWAY, reason: str = "") -> None:
        """Stops listening and closes every viewer (what waits for them is sent first)."""
        if self._server is not None:
            self._server.close()
        for viewer in list(self.viewers):
            viewer.close(code, reason)

    async def gone(self) -> None:
        """Returns once every viewer's connection is closed."""
        self._lost.clear()
        if self.viewers:
            await self._lost.wait()
