"""One port for a view: the page over HTTP, and its WebSocket, on the caller's event loop.

``GET /`` serves the page, ``GET /view.js`` and ``GET /view.css`` its script and
style (nothing else: no CDN, no font), each with a Content-Security-Policy that
lets the page load only these and talk only to this server. ``GET /ws`` with a
WebSocket handshake opens a :class:`Viewer`. One request per HTTP connection.

A viewer never slows the sender: frames go out while the connection's buffer is
below its high-water mark; past it (a viewer that reads slowly, or not at all)
each new frame replaces the one waiting, and only the latest is sent when the
buffer drains (latest frame wins). Text messages (events) wait in a bounded
queue, the oldest dropped first and counted.

Requests are checked as a page's server should be: the ``Host`` of a loopback
server must be a loopback name (a page of another site cannot reach it by DNS
rebinding), and a WebSocket handshake that comes from a page must come from
this server's own page (``Origin``). A viewer's messages are JSON objects of
bounded size and depth (:func:`~cas_async.live._protocol.read_client_message`).

The server has a production server's limits (:class:`ServerLimits`): request
and idle time-outs, a cap on connections (503 past it, counted in
:attr:`ViewServer.refused`), and its own accept loop (:class:`Acceptor`), which
backs off when the process is out of file descriptors. Nothing here arms a loop
timer: a thread sweeps the connections on the wall clock
(:class:`~cas_async.live._pacer.WallTicker`), so the server runs on a virtual-time
loop as on any other, and on asyncio's loops and uvloop's alike.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import socket
import time
from collections import Counter
from collections.abc import Callable
from importlib.resources import files
from typing import Any, Final, final

from ._acceptor import Acceptor
from ._connection import Connection
from ._limits import ServerLimits
from ._pacer import WallTicker
from ._protocol import read_client_message
from ._viewer import Viewer
from ._websocket import CloseCode, Opcode, frame

__all__ = ["ViewServer", "is_loopback"]

_ASSETS: Final = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/view.js": ("view.js", "text/javascript; charset=utf-8"),
    "/view.css": ("view.css", "text/css; charset=utf-8"),
}
BACKLOG: Final = 128
"""Connections the kernel holds for the server before it accepts them."""
SEND_BUFFER: Final = 256 * 1024
"""Bytes the kernel may buffer for a connection (``SO_SNDBUF``, which Linux doubles), at
most: a viewer that stops reading holds this (and :data:`~._viewer.HIGH_WATER` of ours),
where the kernel's own tuning would let it grow to megabytes."""

_NUMERIC: Final = socket.AI_NUMERICHOST


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
class ViewServer:
    """The page and its WebSockets on one port (see the module docs).

    Args:
        on_open: called with each new viewer (send it the hello there).
        on_message: called with each message a viewer sends (a JSON object).
        limits: time-outs and the cap on connections.
        clock: the wall clock, in seconds (the time-outs' and the sweeps').
    """

    def __init__(
        self,
        on_open: Callable[[Viewer], None],
        on_message: Callable[[Viewer, dict[str, Any]], None] | None = None,
        *,
        limits: ServerLimits | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._on_open = on_open
        self._on_message = on_message
        self._limits = limits if limits is not None else ServerLimits()
        self._clock = clock
        self.assets = _load_assets()
        self.viewers: list[Viewer] = []
        """The open viewers."""
        self._served: set[Connection] = set()  # admitted: under the cap
        self._turned_away: set[Connection] = set()  # answered 503, closing
        self._opening: set[asyncio.Task[Any]] = set()  # accepted, not yet connected
        self._acceptor: Acceptor | None = None
        self._ticker: WallTicker | None = None
        self._loopback = True
        self.host = ""
        self.port = 0
        self.connected = asyncio.Event()
        """Set once a viewer has opened its WebSocket."""
        self._lost = asyncio.Event()
        self.refused: Counter[str] = Counter()
        """Connections refused, by reason: ``busy`` (past the cap, 503) and
        ``fd_exhausted`` (accepts that failed for want of a file descriptor)."""

    @property
    def limits(self) -> ServerLimits:
        """The server's limits."""
        return self._limits

    def now(self) -> float:
        """The server's wall clock, in seconds."""
        return self._clock()

    async def start(self, host: str, port: int, sock: socket.socket | None = None) -> None:
        """Listens on ``host``, ``port`` (0: a free one; :attr:`port` says which), or on ``sock``.

        Raises:
            OSError: the address cannot be bound.
        """
        loop = asyncio.get_running_loop()
        given = sock is not None
        if sock is None:
            sock = await _bound(loop, host.strip("[]"), port)
        self._acceptor = Acceptor(sock, self._accepted, self._clock, self._limits.tick)
        address = self._acceptor.address
        self.host, self.port = (address[0] if given else host), address[1]
        self._loopback = is_loopback(self.host)
        self._ticker = WallTicker(loop, self._limits.tick, self.sweep)

    def _accepted(self, sock: socket.socket) -> None:
        with contextlib.suppress(OSError):  # a viewer that stalls holds this much in the kernel
            if sock.getsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF) > SEND_BUFFER:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER)
        loop = asyncio.get_running_loop()
        task = loop.create_task(loop.connect_accepted_socket(lambda: Connection(self), sock))
        self._opening.add(task)
        task.add_done_callback(lambda done: self._connected(done, sock))

    def _connected(self, task: asyncio.Task[Any], sock: socket.socket) -> None:
        self._opening.discard(task)
        if task.cancelled() or task.exception() is not None:  # closed first, or the client went
            sock.close()

    def admit(self, connection: Connection) -> bool:
        """A new connection: whether it is served (``False``: past the cap, answered 503)."""
        if len(self._served) >= self._limits.max_connections:
            self._turned_away.add(connection)
            self.refused["busy"] += 1
            return False
        self._served.add(connection)
        return True

    @property
    def connections(self) -> int:
        """Connections open now (served and turned away)."""
        return len(self._served) + len(self._turned_away)

    def sweep(self) -> None:
        """Applies the time-outs to every connection (the ticker calls it every ``tick``)."""
        now = self._clock()
        for connection in [*self._served, *self._turned_away]:
            connection.check(now)
        if self._acceptor is not None:
            self._acceptor.tick(now)
            self.refused["fd_exhausted"] = self._acceptor.exhausted
            if not self.refused["fd_exhausted"]:
                del self.refused["fd_exhausted"]

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
        """A viewer sent a text message: a JSON object, bounded, for ``on_message``.

        Raises:
            ProtocolError: the message is too deep (1008); the viewer is closed.
        """
        if self._on_message is None:
            return
        message = read_client_message(text)
        if message is not None:
            self._on_message(viewer, message)

    def lost(self, connection: Connection, viewer: Viewer | None) -> None:
        """A connection is gone (with its viewer, if it had become one)."""
        self._served.discard(connection)
        self._turned_away.discard(connection)
        if viewer is None:
            return
        with contextlib.suppress(ValueError):
            self.viewers.remove(viewer)
        if not self.viewers:
            self._lost.set()

    def broadcast_frame(self, data: bytes) -> None:
        """Sends a frame to every viewer (held back for the slow ones), framed once."""
        framed = frame(Opcode.BINARY, data)
        for viewer in self.viewers:
            viewer.send_framed(framed)

    def broadcast_text(self, text: str) -> None:
        """Sends a text message to every viewer."""
        for viewer in self.viewers:
            viewer.send_text(text)

    def close(self, code: CloseCode = CloseCode.GOING_AWAY, reason: str = "") -> None:
        """Stops listening and closes every viewer (what waits for them is sent first).

        Connections that are no viewer are cut; a viewer's is cut by the sweep if it
        does not take its close frame within the request time-out.
        """
        if self._acceptor is not None:
            self._acceptor.close()
        if self._ticker is not None:
            self._ticker.close()
        for viewer in list(self.viewers):
            viewer.close(code, reason)
        for task in list(self._opening):
            task.cancel()
        for connection in [*self._served, *self._turned_away]:
            connection.cut()

    async def gone(self) -> None:
        """Returns once every viewer's connection is closed."""
        self._lost.clear()
        if self.viewers:
            await self._lost.wait()

    def abort(self) -> None:
        """Cuts every connection still open (after :meth:`close`, for viewers that never left)."""
        for connection in [*self._served, *self._turned_away]:
            connection.cut(viewers=True)


async def _bound(loop: asyncio.AbstractEventLoop, host: str, port: int) -> socket.socket:
    """A listening socket on ``host`` (a name or an address) and ``port``.

    Raises:
        OSError: no address of ``host`` can be bound.
    """
    try:  # an address needs no resolver (which would take a thread)
        infos = socket.getaddrinfo(
            host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE | _NUMERIC
        )
    except socket.gaierror:
        infos = await loop.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    error: OSError | None = None
    for family, kind, proto, _, address in infos:
        sock = socket.socket(family, kind, proto)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            sock.bind(address)
            sock.listen(BACKLOG)
        except OSError as exc:
            sock.close()
            error = exc
            continue
        return sock
    raise error if error is not None else OSError(f"no address for {host!r}")
