"""A UDP socket driven directly by a selector event loop, reading in batches.

The stdlib loop's datagram transport reads one datagram per loop pass into a fresh
256 KiB buffer: a burst then costs one loop pass (and one task wake-up in the
receiving layer) per datagram, and glibc may serve each buffer with an mmap. Here
the socket is read until empty (at most ``BATCH`` datagrams per readable event),
so a burst arrives as one batch; the batch grows once the socket has kept having
datagrams for a while (:data:`GROW_AFTER`), so a lone datagram costs no extra
read. Sends go straight to ``sendto``; when the kernel buffer is full they wait
in a backlog flushed when the socket is writable, as the asyncio transport does,
but bounded (:data:`MAX_BACKLOG`). uvloop already batches, and keeps its own transport.

Nothing is lost without a count: the sink's ``transport_dropped`` is called once per
datagram refused by a full backlog (``"send_backlog_full"``), still in the backlog
at :meth:`SocketWire.close` (``"unsent_at_close"``), or refused by the socket
(``"socket_error"``, which also counts errors reported on receive).
"""

from __future__ import annotations

import asyncio
import socket
from collections import deque
from typing import Any, Final, Protocol

from .._core._transport_contract import drop_socket_error

__all__ = ["Receiver", "SocketWire"]

BATCH: Final = 64
"""Datagrams read per readable event at most, so one busy socket cannot starve the loop."""

MAX_BACKLOG: Final = 1024
"""Datagrams waiting for a writable socket at most; more are dropped and counted.

A socket that stays unwritable (a send buffer the kernel cannot drain) would
otherwise grow the backlog, and memory, for as long as layers keep sending. UDP
promises no delivery, so dropping at a bound breaks no guarantee; 1024 datagrams on
top of what the kernel buffer holds still ride out a burst, and cap the memory held
(64 MiB even at the largest datagram size).
"""

GROW_AFTER: Final = 8
"""Readable events in a row that each fill the read budget before it grows.

A read that finds the socket empty costs a failed syscall and an exception. With
the budget doubling after every full event, a ping-pong (one datagram per event)
paid that on every second datagram: 10% of a UDP round trip on the stdlib loop.
Waiting for eight full events in a row makes it one in nine, and costs a burst
eight single reads before its batches grow.
"""

_RECV_SIZE: Final = 65_536


class Receiver(Protocol):
    """Where a :class:`SocketWire` delivers: datagrams with their source address."""

    def datagram_received(self, data: bytes, addr: Any) -> None:
        """One datagram and the address it came from."""

    def transport_dropped(self, reason: str, detail: str) -> None:
        """A datagram lost here (counted by reason)."""


class SocketWire:
    """Sends and receives datagrams on one non-blocking socket."""

    __slots__ = ("_backlog", "_budget", "_full", "_loop", "_sink", "_sock")

    def __init__(
        self, loop: asyncio.AbstractEventLoop, sock: socket.socket, sink: Receiver
    ) -> None:
        sock.setblocking(False)
        self._loop = loop
        self._sock = sock
        self._sink = sink
        self._backlog: deque[tuple[bytes, Any]] = deque()
        self._budget = 1  # datagrams read per readable event (see _read_ready)
        self._full = 0  # readable events in a row that read the whole budget
        loop.add_reader(sock.fileno(), self._read_ready)

    def get_extra_info(self, name: str) -> Any:
        """``"socket"`` and ``"sockname"``, as an asyncio transport answers them."""
        return {"socket": self._sock, "sockname": self._sock.getsockname()}.get(name)

    def _read_ready(self) -> None:
        # Reads up to a budget that adapts (see GROW_AFTER): it doubles on each event
        # that fills it once GROW_AFTER in a row have (a burst), and falls back to
        # what there was when a read finds the socket empty.
        recvfrom, sink, budget = self._sock.recvfrom, self._sink, self._budget
        for n in range(budget):
            try:
                data, addr = recvfrom(_RECV_SIZE)
            except (BlockingIOError, InterruptedError):
                self._budget, self._full = n or 1, 0
                return
            except OSError as exc:  # e.g. ICMP port unreachable reported on the socket
                drop_socket_error(sink, exc)
                return
            sink.datagram_received(data, addr)
        self._full += 1
        if self._full >= GROW_AFTER:
            self._budget = min(2 * budget, BATCH)

    def sendto(self, data: bytes, addr: Any) -> None:
        """Sends now, or queues until the socket is writable (never blocks).

        Behind earlier queued datagrams it queues too, to keep send order; with
        :data:`MAX_BACKLOG` already queued, the datagram is dropped and counted.
        """
        backlog = self._backlog
        if not backlog:
            try:
                self._sock.sendto(data, addr)
                return
            except (BlockingIOError, InterruptedError):
                self._loop.add_writer(self._sock.fileno(), self._write_ready)
            except OSError as exc:
                drop_socket_error(self._sink, exc)
                return
        elif len(backlog) >= MAX_BACKLOG:
            self._sink.transport_dropped(
                "send_backlog_full",
                f"datagram of {len(data)} bytes to {addr}: {len(backlog)} already wait "
                "for the socket to drain",
            )
            return
        backlog.append((data, addr))

    def _write_ready(self) -> None:
        backlog = self._backlog
        while backlog:
            data, addr = backlog[0]
            try:
                self._sock.sendto(data, addr)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                drop_socket_error(self._sink, exc)
            backlog.popleft()
        self._loop.remove_writer(self._sock.fileno())

    def close(self) -> None:
        """Stops reading and writing and closes the socket; idempotent.

        Datagrams still in the backlog are lost, each counted as ``"unsent_at_close"``.
        """
        if self._sock.fileno() >= 0:
            self._loop.remove_reader(self._sock.fileno())
            self._loop.remove_writer(self._sock.fileno())
            self._sock.close()
        backlog, sink = self._backlog, self._sink
        while backlog:
            data, addr = backlog.popleft()
            sink.transport_dropped("unsent_at_close", f"datagram of {len(data)} bytes to {addr}")
