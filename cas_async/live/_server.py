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
from collections.abc import Callable
from importlib.resources import files
from typing import Final, final

from ._connection import Connection
from ._viewer import Viewer
from ._websocket import CloseCode

__all__ = ["ViewServer", "is_loopback"]

_ASSETS: Final = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/view.js": ("view.js", "text/javascript; charset=utf-8"),
    "/view.css": ("view.css", "text/css; charset=utf-8"),
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
            self._server = await loop.create_server(lambda: Connection(self), sock=sock)
        else:
            self._server = await loop.create_server(
                lambda: Connection(self), host.strip("[]"), port, reuse_address=True
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
