"""The view's listening socket, accepted from by the server itself: :class:`Acceptor`.

asyncio's own server accepts in a loop that, when the process is out of file
descriptors (``EMFILE``), logs a traceback for every failed accept, up to a
hundred a pass, and tries again after one second of the *loop's* clock, which on a
virtual-time loop is no time at all: the loop spins, writing megabytes of
tracebacks. Here the socket's readiness calls :meth:`Acceptor.ready`, which takes
at most :data:`BATCH` connections a pass and hands each to ``accepted``; when the
process or the system is out of descriptors, it stops watching the socket, says
so once for the whole episode, and looks again after a back-off counted in wall
seconds (:meth:`Acceptor.tick`, from the server's sweep). The episode ends at the
first connection accepted, which is said too. The connections waiting meanwhile
stay in the kernel's backlog. The same code runs on asyncio's loops and uvloop's.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import socket
from collections.abc import Callable
from typing import Final, final

__all__ = ["BATCH", "Acceptor"]

BATCH: Final = 32
"""Connections accepted in one pass of the loop, at most (the rest wait for the next)."""
_EXHAUSTED: Final = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})

_log = logging.getLogger("cas_async.live")


def _open_files_limit() -> str:
    try:
        import resource
    except ImportError:  # not on this platform
        return "unknown"
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    return "unlimited" if soft == resource.RLIM_INFINITY else str(soft)


@final
class Acceptor:
    """Accepts from ``sock`` on the running loop (see the module docs).

    Args:
        sock: a listening socket; the acceptor owns it from now on.
        accepted: called with each accepted socket (non-blocking).
        clock: the wall clock, in seconds.
        backoff: wall seconds without accepting after the descriptors ran out.
    """

    def __init__(
        self,
        sock: socket.socket,
        accepted: Callable[[socket.socket], None],
        clock: Callable[[], float],
        backoff: float,
    ) -> None:
        sock.setblocking(False)
        self._sock = sock
        self._accepted = accepted
        self._clock = clock
        self._backoff = backoff
        self._loop = asyncio.get_running_loop()
        self._watching = False
        self._resume_at: float | None = None  # out of descriptors: when to look again
        self._episode: tuple[float, int] | None = None  # since when, and how many refused
        self.exhausted = 0
        """Accepts that failed for want of a file descriptor (each back-off's first)."""
        self._watch()

    @property
    def address(self) -> tuple[str, int]:
        """The socket's host and port."""
        host, port = self._sock.getsockname()[:2]
        return str(host), int(port)

    def _watch(self) -> None:
        if not self._watching and self._sock.fileno() >= 0:
            self._loop.add_reader(self._sock.fileno(), self.ready)
            self._watching = True

    def _unwatch(self) -> None:
        if self._watching:
            self._loop.remove_reader(self._sock.fileno())
            self._watching = False

    def ready(self) -> None:
        """The socket is readable: accepts what waits, up to :data:`BATCH`."""
        for _ in range(BATCH):
            try:
                connection, _ = self._sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                if exc.errno in _EXHAUSTED:
                    self._out_of_descriptors(exc)
                    return
                continue  # the client gave up before we took it (ECONNABORTED, ...)
            if self._episode is not None:
                since, refused = self._episode
                self._episode = None
                _log.warning(
                    "live view: accepting connections again, after %.0f s out of file "
                    "descriptors (%d accepts failed)",
                    self._clock() - since,
                    refused,
                )
            connection.setblocking(False)
            self._accepted(connection)

    def _out_of_descriptors(self, exc: OSError) -> None:
        self.exhausted += 1
        self._unwatch()
        now = self._clock()
        self._resume_at = now + self._backoff
        if self._episode is None:
            self._episode = (now, 1)
            _log.warning(
                "live view: out of file descriptors (%s; open-file limit %s): not accepting "
                "connections for %g s at a time until one is free",
                exc.strerror or exc,
                _open_files_limit(),
                self._backoff,
            )
        else:
            self._episode = (self._episode[0], self._episode[1] + 1)

    def tick(self, now: float) -> None:
        """The server's sweep: after a back-off, watches the socket again."""
        # Half a back-off early: the sweep that comes about a back-off later resumes.
        if self._resume_at is not None and now >= self._resume_at - self._backoff / 2:
            self._resume_at = None
            self._watch()
            self.ready()  # what waits in the backlog does not make the socket readable anew

    def close(self) -> None:
        """Stops accepting and closes the socket; idempotent."""
        self._resume_at = None
        if self._sock.fileno() >= 0:
            self._unwatch()
            self._sock.close()
