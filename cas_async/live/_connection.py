"""One TCP connection to the view's port: an HTTP request, then perhaps a WebSocket.

``GET /``, ``/view.js`` and ``/view.css`` are answered from the host's assets with
a Content-Security-Policy and the connection closed (one request per connection);
``GET /ws`` with a WebSocket handshake becomes a :class:`Viewer`. Anything else
gets the HTTP status that says why: a repeated ``Host`` (or any header the server
reads) is refused, 400, as RFC 9112 asks, since two servers could read two hosts.

Nothing here arms a timer: the server's sweep (from a thread, on the wall clock)
calls :meth:`Connection.check`, which answers a request head that is not complete
after the request timeout with 408, cuts a connection that does not take its answer
or close frame as fast, pings a viewer that has been silent for a while and closes
one that stays silent (:class:`~cas_async.live._limits.ServerLimits`). The transport
may be asyncio's or uvloop's (which is no ``asyncio.Transport`` subclass).

Nothing a client sends ends in a traceback: what the server's handlers raise on a
viewer's message closes that viewer (1011) and is logged at its 1st, 10th, 100th...
occurrence.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from functools import partial
from typing import Final, Protocol, cast

from ._limits import BUSY_LINGER, ServerLimits
from ._viewer import HIGH_WATER, Viewer
from ._websocket import CloseCode, FrameReader, Opcode, ProtocolError, accept_key

__all__ = ["CSP", "Connection", "Host"]

REQUEST_LIMIT: Final = 16 * 1024
"""Bytes of an HTTP request head; a longer one is refused (431)."""
MESSAGE_LIMIT: Final = 4 * 1024
"""Bytes of a viewer's message (the page sends a few dozen: a seek)."""
_SINGLE: Final = frozenset(
    {
        "host",
        "origin",
        "upgrade",
        "connection",
        "sec-websocket-key",
        "sec-websocket-version",
        "content-length",
        "transfer-encoding",
    }
)
"""Headers a request may hold once at most (two ``Host`` could name two servers)."""
_BUSY: Final = (
    b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain; charset=utf-8\r\n"
    b"Content-Length: 40\r\nRetry-After: 5\r\nCache-Control: no-store\r\n"
    b"Connection: close\r\n\r\nthe view serves all the viewers it can\r\n"
)
_log = logging.getLogger("cas_async.live")
_failures = [0]  # handlers' failures on a viewer's message, in this process (logged sparsely)
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
    408: "Request Timeout",
    426: "Upgrade Required",
    431: "Request Header Fields Too Large",
}


class Host(Protocol):
    """What a connection asks of the server it belongs to."""

    @property
    def assets(self) -> dict[str, tuple[bytes, str]]:
        """The files served, by path: their bytes and content type."""

    @property
    def limits(self) -> ServerLimits:
        """The server's limits (time-outs, connections)."""

    def now(self) -> float:
        """The wall clock, in seconds."""

    def admit(self, connection: Connection) -> bool:
        """A new connection: whether it is served (``False``: the server is full)."""

    def refuse(self, headers: dict[str, str]) -> str | None:
        """Why a request with these headers is refused, or ``None``."""

    def opened(self, viewer: Viewer) -> None:
        """A viewer completed its handshake."""

    def received(self, viewer: Viewer, text: str) -> None:
        """A viewer sent a text message."""

    def lost(self, connection: Connection, viewer: Viewer | None) -> None:
        """A connection is gone (with its viewer, if it had become one)."""


class Connection(asyncio.Protocol):
    """One TCP connection: an HTTP request, then perhaps a WebSocket."""

    def __init__(self, server: Host) -> None:
        self._server = server
        self._transport: asyncio.Transport | None = None
        self._head = bytearray()
        self._viewer: Viewer | None = None
        self._reader = FrameReader(MESSAGE_LIMIT)
        self._draining = False  # after a protocol error: read, drop, until the client closes
        self._phase = "head"  # head, closing (answered), websocket, draining, busy
        self._since = 0.0  # when the phase began (the server's wall clock)
        self._heard = 0.0  # when the client last sent anything
        self._pinged = False  # since it was last heard

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # uvloop's TCPTransport has every method of asyncio.Transport, but is no subclass.
        self._transport = cast(asyncio.Transport, transport)
        self._transport.set_write_buffer_limits(high=HIGH_WATER)
        self._since = self._heard = self._server.now()
        if not self._server.admit(self):
            self._turn_away()

    def _turn_away(self) -> None:
        """The server is full: 503, then a half-close (what the client sends is dropped)."""
        transport = self._transport
        assert transport is not None
        self._enter("busy")
        self._draining = True
        transport.write(_BUSY)
        if transport.can_write_eof():
            transport.write_eof()
        else:
            transport.close()

    def _enter(self, phase: str) -> None:
        self._phase, self._since = phase, self._server.now()

    def check(self, now: float) -> None:
        """The server's sweep: time-outs, pings (see the module docs)."""
        transport = self._transport
        if transport is None:
            return
        limits = self._server.limits
        phase, age = self._phase, now - self._since
        if phase == "head" and age > limits.request_timeout:
            self._respond(408, b"the request head did not come in time\n")
        elif (phase == "busy" and age > BUSY_LINGER) or (
            phase in ("closing", "draining") and age > limits.request_timeout
        ):
            transport.abort()  # it does not take what we said, nor close its side
        elif phase == "websocket" and self._viewer is not None:
            silent = now - self._heard
            if silent > limits.idle_timeout:
                self._viewer.close(CloseCode.GOING_AWAY, "idle")
                self._enter("closing")
            elif silent > limits.ping_every and not self._pinged:
                self._pinged = True
                self._viewer.control(Opcode.PING, b"")

    def cut(self, *, viewers: bool = False) -> None:
        """Aborts the connection (a viewer's only when ``viewers``: it is closed otherwise)."""
        if self._transport is not None and (viewers or self._viewer is None):
            self._transport.abort()

    def data_received(self, data: bytes) -> None:
        self._heard = self._server.now()
        self._pinged = False
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
            name = name.strip().lower()
            if name in headers and name in _SINGLE:
                self._respond(400, f"a repeated {name} header\n".encode("latin-1"))
                return
            headers[name] = value.strip()
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
        self._enter("websocket")
        self._guarded(viewer, lambda: self._server.opened(viewer))

    def _guarded(self, viewer: Viewer, call: Callable[[], None]) -> None:
        """Runs a handler of the server's for ``viewer``; what it raises closes only that viewer."""
        try:
            call()
        except ProtocolError as error:  # the client's message broke the view's protocol
            self._fail(viewer, error.code, error.reason)
        except Exception as exc:  # a bug, or input no check foresaw: this viewer alone goes
            _failures[0] += 1
            if _is_power_of_ten(_failures[0]):
                _log.error(
                    "live view: a viewer closed (1011) after the server failed on it: %s: %s "
                    "(%d so far)",
                    type(exc).__name__,
                    str(exc)[:200],
                    _failures[0],
                )
            self._fail(viewer, CloseCode.INTERNAL_ERROR, "server error")

    def _fail(self, viewer: Viewer, code: CloseCode, reason: str) -> None:
        self._draining = True
        self._enter("draining")
        viewer.fail(code, reason)

    def _websocket_data(self, viewer: Viewer, data: bytes) -> None:
        try:
            messages = self._reader.feed(data)
        except ProtocolError as error:
            self._fail(viewer, error.code, error.reason)
            return
        for message in messages:
            if message.opcode is Opcode.PING:
                viewer.control(Opcode.PONG, message.payload)
            elif message.opcode is Opcode.CLOSE:
                code = message.payload[:2] if len(message.payload) >= 2 else b""
                viewer.control(Opcode.CLOSE, code)
                viewer.closed = True
                self._enter("closing")
                if self._transport is not None:
                    self._transport.close()
                return
            elif message.opcode is Opcode.TEXT:
                text = message.payload.decode("utf-8")
                self._guarded(viewer, partial(self._server.received, viewer, text))
                if self._draining:
                    return
            elif message.opcode is Opcode.BINARY:
                self._fail(viewer, CloseCode.UNSUPPORTED, "this server reads text messages only")
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
        self._enter("closing")
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
        self._transport = None
        if self._viewer is not None:
            self._viewer.closed = True
        self._server.lost(self, self._viewer)


def _is_power_of_ten(n: int) -> bool:
    while n >= 10 and n % 10 == 0:
        n //= 10
    return n == 1
