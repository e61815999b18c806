"""The default transport: one asyncio UDP datagram endpoint per robot.

A :class:`UdpDirectory` maps robot ids to ``(host, port)``, hosts as IP literals.
Robots started in this process with no configured address bind ``host`` (127.0.0.1
by default) on a port the OS picks, enter it in the directory and remove it again
when they close; robots in other processes or hosts are entered from configuration
with :meth:`UdpDirectory.add`. A robot whose own id has a configured address binds
exactly that address, and the entry outlives the robot: a restarted robot binds the
same address again, where the others keep sending.

Receive buffers are enlarged (4 MiB asked; the kernel caps it at ``rmem_max``)
because the stdlib loop reads one datagram per loop pass and a burst would
otherwise overflow the default buffer and be dropped by the kernel. When the kernel
grants less than asked, the transport logs it once, with the setting to raise.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import logging
import socket
import warnings
from collections.abc import Iterable, Iterator, Mapping
from typing import Any, Final, Protocol, final

from .._core._transport_contract import DatagramSink, Endpoint, Transport, drop_socket_error
from .._errors import ConfigurationError, RobotStateError, UnknownRobotError
from .._types import Address, RobotId
from ._batched_socket import SocketWire
from ._fd_limit import ensure_descriptors

__all__ = ["MAX_UDP_PAYLOAD", "InsecureBindWarning", "UdpDirectory", "UdpTransport"]

MAX_UDP_PAYLOAD: Final = 65_507
"""Largest IPv4 UDP payload; larger datagrams cannot be sent."""

_DEFAULT_BUFFER: Final = 4 * 1024 * 1024

_log = logging.getLogger(__name__)

HostPort = tuple[str, int]


class InsecureBindWarning(UserWarning):
    """A robot listens beyond loopback with no authentication: anyone reaching it can send."""


class UdpDirectory:
    """Where each robot listens: ``robot_id -> (host, port)``.

    Hosts are IP literals (IPv4 or IPv6), never hostnames: a send must not resolve a
    name, because the stdlib loop would block on a DNS lookup for every datagram and
    uvloop refuses outright. Resolve names once, before entering them.

    Args:
        addresses: known addresses, e.g. from a scenario file.

    Raises:
        ConfigurationError: an address has a hostname or a port outside 0..65535.
    """

    def __init__(self, addresses: Mapping[RobotId, HostPort] | None = None) -> None:
        self._addresses: dict[RobotId, HostPort] = {}
        # Source address -> robot: how a received datagram's sender is known. IPv6
        # source addresses come as (host, port, flowinfo, scope_id).
        self._senders: dict[tuple[Any, ...], RobotId] = {}
        # Port -> robot, for robots entered at a wildcard address (0.0.0.0, ::): their
        # datagrams come from whatever interface address the kernel picks.
        self._wildcards: dict[int, RobotId] = {}
        # Told when a robot is entered or removed (a dict as an ordered set).
        self._watchers: dict[DatagramSink, None] = {}
        for robot_id, (host, port) in (addresses or {}).items():
            self.add(robot_id, host, port)

    def add(self, robot_id: RobotId, host: str, port: int) -> None:
        """Records (or replaces) where ``robot_id`` listens.

        Raises:
            ConfigurationError: ``host`` is not an IP literal, or ``port`` is not in
                0..65535.
        """
        try:
            # ip_address() would also take an int: only a string is an IP literal here.
            ipaddress.ip_address(host if isinstance(host, str) else "")
        except ValueError:
            raise ConfigurationError(
                f"robot {robot_id}: UDP host must be an IP address (IPv4 or IPv6), got "
                f"{host!r}; resolve the hostname first (e.g. with socket.getaddrinfo) or "
                "use 127.0.0.1"
            ) from None
        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise ConfigurationError(f"robot {robot_id}: port must be in 0..65535, got {port!r}")
        new = robot_id not in self._addresses
        self._forget(robot_id)
        self._addresses[robot_id] = (host, port)
        for source in _source_forms(host, port):
            self._senders[source] = robot_id
        if _is_wildcard(host):
            self._wildcards[port] = robot_id
        if new:
            for watcher in list(self._watchers):
                watcher.robot_joined(robot_id)

    def remove(self, robot_id: RobotId) -> None:
        """Forgets ``robot_id``; no error when unknown."""
        if self._forget(robot_id):
            for watcher in list(self._watchers):
                watcher.robot_left(robot_id)

    def _forget(self, robot_id: RobotId) -> bool:
        old = self._addresses.pop(robot_id, None)
        if old is None:
            return False
        for source in _source_forms(*old):
            if self._senders.get(source) == robot_id:
                del self._senders[source]
        if self._wildcards.get(old[1]) == robot_id:
            del self._wildcards[old[1]]
        return True

    def watch(self, sink: DatagramSink) -> None:
        """Tells ``sink`` of every robot entered (``robot_joined``) or removed (``robot_left``)."""
        self._watchers[sink] = None

    def unwatch(self, sink: DatagramSink) -> None:
        """Stops telling ``sink``; no error when it was not watching."""
        self._watchers.pop(sink, None)

    @property
    def senders(self) -> Mapping[tuple[Any, ...], RobotId]:
        """Robot by exact source address, kept up to date (read-only; see :meth:`sender`).

        The per-datagram fast path: one dict lookup, :meth:`sender` only on a miss.
        """
        return self._senders

    def sender(self, source: Any) -> RobotId | None:
        """The robot that sends from ``source`` (a datagram's source address), or ``None``.

        A robot entered at a wildcard address (``0.0.0.0``, ``::``) sends from any of
        the host's addresses: it is known by its port alone. On its host nobody else
        can bind that port, but a stranger on another host can send from it: without
        a swarm key, enter robots at specific addresses.
        """
        robot = self._senders.get(source)
        if robot is None and self._wildcards:
            robot = self._wildcards.get(source[1])
        return robot

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


def _is_loopback(host: str) -> bool:
    """Whether ``host`` (a bound IP literal) only takes datagrams from this machine."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # not an IP literal: assume the worst
        return False


def _is_wildcard(host: str) -> bool:
    """Whether ``host`` is the unspecified address, bound to every interface."""
    try:
        return ipaddress.ip_address(host).is_unspecified
    except ValueError:
        return False


def _source_forms(host: str, port: int) -> tuple[tuple[Any, ...], ...]:
    """How a datagram from ``host:port`` names its source (IPv6 adds flowinfo, scope)."""
    if ":" in host:
        return ((host, port), (host, port, 0, 0))
    return ((host, port),)


class _Wire(Protocol):
    """What an endpoint sends through: an asyncio transport or a :class:`SocketWire`."""

    def sendto(self, data: bytes, addr: Any) -> None: ...
    def close(self) -> None: ...
    def get_extra_info(self, name: str) -> Any: ...


class _Protocol(asyncio.DatagramProtocol):
    """Hands datagrams to the robot, naming the sender by its source address."""

    __slots__ = ("_directory", "_senders", "_sink")

    def __init__(self, sink: DatagramSink, directory: UdpDirectory) -> None:
        self._sink = sink
        self._senders = directory.senders  # read per datagram: skip the method call
        self._directory = directory

    def datagram_received(self, data: bytes, addr: Any) -> None:
        sender = self._senders.get(addr)
        if sender is None:  # a wildcard-bound robot, a stranger, or nobody known
            sender = self._directory.sender(addr)
        self._sink.datagram_received(data, sender)

    def transport_dropped(self, reason: str, detail: str) -> None:
        self._sink.transport_dropped(reason, detail)

    def error_received(self, exc: Exception) -> None:
        # ICMP errors (e.g. port unreachable after a peer stopped) land here.
        drop_socket_error(self._sink, exc)


@final
class UdpEndpoint(Endpoint):
    """A robot's UDP socket.

    Args:
        robot_id: the robot this socket belongs to.
        transport: the bound socket.
        sink: the robot, told about datagrams that could not be sent.
        directory: where peers are looked up on every send.
        address: the bound address.
        registered: the entry :meth:`UdpTransport.open` made in ``directory`` (the
            bound address), or ``None`` when it kept a configured entry as it was.
        configured: the entry ``directory`` had before ``open``, put back at close
            in place of ``registered``.
    """

    def __init__(
        self,
        robot_id: RobotId,
        transport: _Wire,
        sink: DatagramSink,
        directory: UdpDirectory,
        address: HostPort,
        *,
        registered: HostPort | None,
        configured: HostPort | None,
    ) -> None:
        self.robot_id = robot_id
        self.max_datagram_size = MAX_UDP_PAYLOAD
        self._transport = transport
        self._sink = sink
        self._addresses = directory._addresses  # read on every send: skip the method call
        self._directory = directory
        self._address = address
        self._registered = registered
        self._configured = configured
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
        try:
            self._transport.sendto(data, addr)
        except ValueError as exc:
            # uvloop raises where the stdlib socket raises OSError (counted by SocketWire):
            # an IPv6 peer seen from an IPv4 socket or the reverse. A peer the socket cannot
            # reach is a lost datagram, not a reason to end the sending layer.
            drop_socket_error(self._sink, exc)

    def peers(self) -> Iterable[RobotId]:
        return [rid for rid in self._addresses if rid != self.robot_id]

    def knows(self, robot_id: RobotId) -> bool:
        return robot_id in self._addresses

    def follow_membership(self, follow: bool) -> None:
        if follow and not self._closed:
            self._directory.watch(self._sink)
        else:
            self._directory.unwatch(self._sink)

    def close(self) -> None:
        """Closes the socket and undoes this endpoint's directory entry, if it made one.

        A configured address stays (robots elsewhere keep sending there, and a restart
        binds it again); an address the OS picked is removed, or the configured entry
        it replaced (port 0) is put back. Nothing changes when someone else has
        replaced the entry meanwhile.
        """
        if self._closed:
            return
        self._closed = True
        self._transport.close()
        self._directory.unwatch(self._sink)
        if self._registered is not None and self._directory.get(self.robot_id) == self._registered:
            if self._configured is None:
                self._directory.remove(self.robot_id)
            else:
                self._directory.add(self.robot_id, *self._configured)


@final
class UdpTransport(Transport):
    """UDP datagrams between robots (the default transport).

    Args:
        directory: robot addresses; a new empty one when omitted.
        host: address robots without a configured address bind (loopback by default);
            a hostname is resolved when binding, and the directory gets the bound IP.
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
        self._capped_buffer_logged = False  # once per transport, not once per robot

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        """Binds a socket for the robot: its configured address, else ``host`` on any port.

        The bound address enters the directory unless the robot's configured entry
        already names it (a configured port 0 is replaced by the port bound).
        """
        live = self._open.get(robot_id)
        if live is not None and not live._closed:
            raise ConfigurationError(f"robot {robot_id} already has an open UDP endpoint")
        configured = self.directory.get(robot_id)
        bind = configured or (self.host, 0)
        loop = asyncio.get_running_loop()
        ensure_descriptors(1)  # this robot's socket: a thousand robots outgrow a soft limit
        try:
            transport = await self._bind(loop, bind, _Protocol(sink, self.directory))
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
        self._check_receive_buffer(sock)
        # The sockname is an IP literal even when ``host`` is a name: fit for the directory.
        host, port = transport.get_extra_info("sockname")[:2]
        registered: HostPort | None = None
        if configured is None or configured[1] == 0:
            registered = (host, port)
            self.directory.add(robot_id, host, port)
        endpoint = self._open[robot_id] = UdpEndpoint(
            robot_id,
            transport,
            sink,
            self.directory,
            (host, port),
            registered=registered,
            configured=configured,
        )
        if not self.authenticated and not _is_loopback(host):
            try:
                warnings.warn(
                    f"robot {robot_id}: UDP socket bound to {host} port {port} accepts "
                    "datagrams from beyond this machine without authentication; anyone who "
                    "can reach it can send this robot messages. Give the swarm a key "
                    "(CAS_ASYNC_SWARM_KEY=<hex> or a key file, see SwarmKey) and wrap the "
                    "transport in AuthenticatedTransport, or bind 127.0.0.1",
                    InsecureBindWarning,
                    stacklevel=2,
                )
            except BaseException:  # warnings turned into errors: no socket left behind
                endpoint.close()
                raise
        return endpoint

    def _check_receive_buffer(self, sock: socket.socket) -> None:
        """Logs once when the kernel grants a smaller receive buffer than asked.

        Nothing fails: robots still talk, but a burst larger than the buffer is
        dropped by the kernel before any robot can count it, so the user must hear
        of it. Linux doubles the size it sets (room for its own bookkeeping) and
        reads back the doubled value, so a buffer granted in full reads back at
        least the size asked.
        """
        if self._capped_buffer_logged:
            return
        try:
            granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        except OSError:  # cannot tell: say nothing rather than fail a working socket
            return
        if granted >= self.receive_buffer:
            return
        self._capped_buffer_logged = True
        _log.warning(
            "UDP receive buffers: asked %d bytes, the kernel grants %d; a burst larger "
            "than that is dropped before any robot sees it. Raise the kernel's cap (on "
            "Linux: sysctl -w net.core.rmem_max=%d), or ask less with "
            "UdpTransport(receive_buffer=...) where bursts stay small",
            self.receive_buffer,
            granted,
            self.receive_buffer,
        )

    @staticmethod
    async def _bind(loop: asyncio.AbstractEventLoop, bind: HostPort, receiver: _Protocol) -> _Wire:
        if isinstance(loop, asyncio.SelectorEventLoop):  # the stdlib loop: read in batches
            infos = await loop.getaddrinfo(*bind, type=socket.SOCK_DGRAM)
            family, kind, proto, _, address = infos[0]
            sock = socket.socket(family, kind, proto)
            try:
                sock.bind(address)
            except OSError:
                sock.close()
                raise
            return SocketWire(loop, sock, receiver)
        # Shielded: cancelled half-way, uvloop leaves the endpoint it made open, and its
        # loop then hangs in close(). Binding on loopback takes microseconds: let it
        # finish, close what it made, and be cancelled after.
        creating = asyncio.ensure_future(
            loop.create_datagram_endpoint(lambda: receiver, local_addr=bind)
        )
        try:
            transport, _ = await asyncio.shield(creating)
        except asyncio.CancelledError:
            with contextlib.suppress(Exception, asyncio.CancelledError):
                made, _ = await creating
                made.close()
            raise
        return transport

    def __repr__(self) -> str:
        return f"UdpTransport(host={self.host!r}, {len(self.directory)} robots)"
