"""One TCP connection to the view's port: an HTTP request, then perhaps a WebSocket.

``GET /``, ``/view.js`` and ``/view.css`` are answered from the host's assets with
a Content-Security-Policy and the connection closed (one request per connection);
``GET /ws`` with a WebSocket handshake becomes a :class:`Viewer`. Anything else
gets the HTTP status that says why. Nothing here arms a timer: the connection
lives on whatever loop the server runs on, virtual time included.
"""

from __future__ import annotations

import asyncio
from typing import Final, Protocol

from ._viewer import HIGH_WATER, Viewer
from ._websocket import CloseCode, FrameReader, Opcode, ProtocolError, accept_key

__all__ = ["CSP", "Connection", "Host"]

REQUEST_LIMIT: Final = 16 * 1024
"""Bytes of an HTTP request head; a longer one is refused (431)."""
MESSAGE_LIMIT: Final = 64 * 1024
"""Bytes of a viewer's message (the page sends a few dozen)."""
CSP: Final = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
    "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
)
_REASONS: Final = {
    200: "OK",
    400: "Bad Request",
    403: "Forbidden",
    404: "Not Found",
    405: "Method Not Allowed",
    426: "Upgrade Required",
    431: "Request Header Fields Too Large",
}


class Host(Protocol):
    """What a connection asks of the server it belongs to."""

    @property
    def assets(self) -> dict[str, tuple[bytes, str]]:
        """The files served, by path: their bytes and content type."""

    def refuse(self, headers: dict[str, str]) -> str | None:
        """Why a request with these headers is refused, or ``None``."""

    def opened(self, viewer: Viewer) -> None:
        """A viewer completed its handshake."""

    def received(self, viewer: Viewer, text: str) -> None:
        """A viewer sent a text message."""

    def lost(self, viewer: Viewer) -> None:
        """A viewer's connection is gone."""


class Connection(asyncio.Protocol):
    """One TCP connection: an HTTP request, then perhaps a WebSocket."""

    def __init__(self, server: Host) -> None:
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
        self._viewer = viewer = Viewer(transport)
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
