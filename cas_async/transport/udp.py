"""The default transport: one asyncio UDP datagram endpoint per robot.

A :class:`UdpDirectory` maps robot ids to ``(host, port)``. Robots started in this
process with no configured address bind ``host`` (127.0.0.1 by default) on a port
the OS picks and enter it in the directory; robots in other processes or hosts are
entered from configuration with :meth:`UdpDirectory.add`. A robot whose own id has
a configured address binds exactly that address.

Receive buffers are enlarged (4 MiB asked; the kernel caps it at ``rmem_max``)
because the stdlib loop reads one datagram per loop pass and a burst would
otherwise overflow the default buffer and be dropped by the kernel.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import Iterable, Iterator, Mapping
from typing import Any, Final, Protocol, final

from .._types import Address, RobotId
from ..errors import ConfigurationError, RobotStateError, UnknownRobotError
from .base import DatagramSink, Endpoint, Transport
from .udp_socket import SocketWire

__all__ = ["MAX_UDP_PAYLOAD", "UdpDirectory", "UdpTransport"]

MAX_UDP_PAYLOAD: Final = 65_507
"""Largest IPv4 UDP payload; larger datagrams cannot be sent."""

_DEFAULT_BUFFER: Final = 4 * 1024 * 1024

HostPort = tuple[str, int]


class UdpDirectory:
    """Where each robot listens: ``robot_id -> (host, port)``.

    Args:
        addresses: known addresses, e.g. from a scenario file.
    """

    def __init__(self, addresses: Mapping[RobotId, HostPort] | None = None) -> None:
        self._addresses: dict[RobotId, HostPort] = {}
        for robot_id, (host, port) in (addresses or {}).items():
            self.add(robot_id, host, port)

    def add(self, robot_id: RobotId, host: str, port: int) -> None:
        """Records (or replaces) where ``robot_id`` listens."""
        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise ConfigurationError(f"robot {robot_id}: port must be in 0..65535, got {port!r}")
        self._addresses[robot_id] = (host, port)

    def remove(self, robot_id: RobotId) -> None:
        """Forgets ``robot_id``; no error when unknown."""
        self._addresses.pop(robot_id, None)

    def get(self, robot_id: RobotId) -> HostPort | None:
        """The address of ``robot_id``, or ``None``."""
        return self._addresses.get(robot_id)

    def __contains__(self, robot_id: object) -> bool:
        return robot_id in self._addresses

    def __iter__(self) -> Iterator[RobotId]:
        return iter(list(self._addresses))

    def __len__(self) -> int:
        return len(self._addresses)

    def __repr__(self) -> str:
        return f"UdpDirectory({self._addresses!r})"


class _Wire(Protocol):
    """What an endpoint sends through: an asyncio transport or a :class:`SocketWire`."""

    def sendto(self, data: bytes, addr: Any) -> None: ...
    def close(self) -> None: ...
    def get_extra_info(self, name: str) -> Any: ...


class _Protocol(asyncio.DatagramProtocol):
    __slots__ = ("_sink",)

    def __init__(self, sink: DatagramSink) -> None:
        self._sink = sink

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self._sink.datagram_received(data)

    def error_received(self, exc: Exception) -> None:
        # ICMP errors (e.g. port unreachable after a peer stopped) land here.
        self._sink.transport_dropped("socket_error", f"{type(exc).__name__}: {exc}")


@final
class UdpEndpoint(Endpoint):
    """A robot's UDP socket."""

    def __init__(
        self,
        robot_id: RobotId,
        transport: _Wire,
        directory: UdpDirectory,
        address: HostPort,
    ) -> None:
        self.robot_id = robot_id
        self.max_datagram_size = MAX_UDP_PAYLOAD
        self._transport = transport
        self._addresses = directory._addresses  # read on every send: skip the method call
        self._directory = directory
        self._address = address
        self._closed = False

    @property
    def address(self) -> Address:
        return self._address

    def send(self, robot_id: RobotId, data: bytes) -> None:
        addr = self._addresses.get(robot_id)
        if addr is None:
            raise UnknownRobotError(
                f"robot {self.robot_id}: no UDP address for robot {robot_id}; "
                "add it to the UdpDirectory"
            )
        if self._closed:
            raise RobotStateError(f"robot {self.robot_id}: UDP endpoint is closed")
        self._transport.sendto(data, addr)

    def peers(self) -> Iterable[RobotId]:
        return [rid for rid in self._addresses if rid != self.robot_id]

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._transport.close()
            if self._directory.get(self.robot_id) == self._address:
                self._directory.remove(self.robot_id)


@final
class UdpTransport(Transport):
    """UDP datagrams between robots (the default transport).

    Args:
        directory: robot addresses; a new empty one when omitted.
        host: address robots without a configured address bind (loopback by default).
        receive_buffer: ``SO_RCVBUF`` asked for each socket, in bytes.
        send_buffer: ``SO_SNDBUF`` asked for each socket, in bytes.
    """

    supports_virtual_time = False

    def __init__(
        self,
        directory: UdpDirectory | None = None,
        *,
        host: str = "127.0.0.1",
        receive_buffer: int = _DEFAULT_BUFFER,
        send_buffer: int = _DEFAULT_BUFFER,
    ) -> None:
        self.directory = directory if directory is not None else UdpDirectory()
        self.host = host
        self.receive_buffer = receive_buffer
        self.send_buffer = send_buffer
        self._open: dict[RobotId, UdpEndpoint] = {}

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        """Binds a socket for the robot and enters its address in the directory."""
        live = self._open.get(robot_id)
        if live is not None and not live._closed:
            raise ConfigurationError(f"robot {robot_id} already has an open UDP endpoint")
        bind = self.directory.get(robot_id) or (self.host, 0)
        loop = asyncio.get_running_loop()
        try:
            transport = await self._bind(loop, bind, sink)
        except OSError as exc:
            raise ConfigurationError(f"robot {robot_id}: cannot bind UDP {bind}: {exc}") from exc
        sock = transport.get_extra_info("socket")
        for option, size in (
            (socket.SO_RCVBUF, self.receive_buffer),
            (socket.SO_SNDBUF, self.send_buffer),
        ):
            # The kernel may refuse sizes above its cap; its default then stays.
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, option, size)
        host, port = transport.get_extra_info("sockname")[:2]
        self.directory.add(robot_id, host, port)
        endpoint = self._open[robot_id] = UdpEndpoint(
            robot_id, transport, self.directory, (host, port)
        )
        return endpoint

    @staticmethod
    async def _bind(loop: asyncio.AbstractEventLoop, bind: HostPort, sink: DatagramSink) -> _Wire:
        if isinstance(loop, asyncio.SelectorEventLoop):  # the stdlib loop: read in batches
            infos = await loop.getaddrinfo(*bind, type=socket.SOCK_DGRAM)
            family, kind, proto, _, address = infos[0]
            sock = socket.socket(family, kind, proto)
            try:
                sock.bind(address)
            except OSError:
                sock.close()
                raise
            return SocketWire(loop, sock, sink)
        transport, _ = await loop.create_datagram_endpoint(lambda: _Protocol(sink), local_addr=bind)
        return transport

    def __repr__(self) -> str:
        return f"UdpTransport(host={self.host!r}, {len(self.directory)} robots)"
