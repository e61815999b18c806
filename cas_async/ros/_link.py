"""A ROS 2 node on Zenoh, without ROS: :class:`RosLink` speaks rmw_zenoh to a robot's router.

One Zenoh session per link, in *client* mode by default: a robot's ``rmw_zenohd``
router does not broker between peers (rmw_zenoh#341, #625), so a session from
another machine must be its client. The link declares a node token (the node shows
in ``ros2 node list``), one token per publisher and subscription (``ros2 topic
info``), and follows everyone's tokens under ``@ros2_lv/<domain>/**`` to know the
graph (:meth:`RosLink.graph`, :meth:`RosLink.wait_for`). Samples and tokens arrive on
Zenoh's threads and reach the loop in batches through one
:class:`~cas_async.transport.zenoh._thread_inbox.ThreadInbox`, as in ``ZenohTransport``.

A peer whose token shows one of our topics with another type or type hash can
never hear us nor we it (the keys differ): the link warns
(:class:`~cas_async.ros.RosTypeMismatchWarning`, naming both hashes) and keeps the
case in :attr:`RosLink.mismatches`.

Anyone on the robot's router can declare tokens and publish samples, so what a
stranger can make the link keep or say is bounded: the graph holds at most
:data:`GRAPH_LIMIT` entities (our own always), :attr:`RosLink.mismatches` at most
:data:`MISMATCH_LIMIT` (the rest counted), and a malformed token or a mismatch is
warned about at its 1st, 10th, 100th... occurrence, with the count. A sample longer
than its subscription's ``max_bytes`` is refused on Zenoh's thread before it is
copied (see :class:`~cas_async.ros.RosSubscription`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Final, Literal

from .. import ConfigurationError, RobotStateError
from ..transport.zenoh import ThreadInbox, loopback_config
from ._endpoints import DEFAULT_MAX_BYTES, RosPublisher, RosSubscription, is_power_of_ten
from ._exceptions import RosTimeout, RosTypeMismatchWarning
from ._extra import import_zenoh
from ._graph import ADMIN_SPACE, GraphEntity, Kind, parse_token
from ._message_types import DISTRO, TypeCatalog
from ._names import data_key, resolve_topic, validate_namespace, validate_node_name
from ._qos import History, QoS, Reliability

__all__ = ["GRAPH_LIMIT", "MISMATCH_LIMIT", "ZENOH_MESSAGE_LIMIT", "RosLink", "TypeMismatch"]

GRAPH_LIMIT: Final = 10_000
"""Entities of other sessions the link's graph holds, at most (the rest counted)."""
MISMATCH_LIMIT: Final = 256
"""Type mismatches :attr:`RosLink.mismatches` keeps, at most (the rest counted)."""
ZENOH_MESSAGE_LIMIT: Final = 1024**3
"""The largest message Zenoh takes by default (``transport/link/rx/max_message_size``)."""

_log = logging.getLogger("cas_async.ros")
_ENDPOINT: Final = re.compile(
    r"(tcp|udp|tls|quic|ws)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.\-]+):\d{1,5}"
)
_Entry = tuple[RosSubscription | None, str | bytes | int, bytes | bool | None]
"""A token (``None``, its key, whether it was put), a sample (the subscription, its
bytes, its attachment), or a sample refused for its size (the subscription, its size)."""


@dataclass(frozen=True, slots=True)
class TypeMismatch:
    """A peer's endpoint on one of our topics whose type or type hash differs from ours."""

    topic: str
    ours: str  # "<DDS type>/<hash>"
    theirs: str
    peer: GraphEntity

    def __str__(self) -> str:
        hint = (
            " (a ROS 2 Humble node: it has no type hashes)"
            if self.peer.type_hash == "TypeHashNotSupported"
            else ""
        )
        return (
            f"{self.peer.node_fqn} ({self.peer.kind}) uses {self.topic} as {self.theirs}, "
            f"we as {self.ours}{hint}: they will never exchange a message"
        )


class RosLink:
    """A ROS 2 node, in a Zenoh session connected to a robot's ``rmw_zenohd``.

    Args:
        node: this node's name (``ros2 node list`` shows ``<namespace>/<node>``).
        namespace: the node's namespace; relative topic names resolve under it.
        domain_id: ``ROS_DOMAIN_ID`` of the robot.
        distro: the ROS 2 distribution spoken (:data:`~cas_async.ros.DISTROS`).
        connect: the router's endpoint(s), ``tcp/HOST:7447`` (rmw_zenohd's port).
        mode: ``"client"`` (through the router: what a foreign session must be) or
            ``"peer"`` (as rmw_zenoh's own nodes, beside a router on the same host).
        listen: endpoints a peer listens on (a client listens on none).
        open_timeout: seconds :meth:`open` waits for the router before it gives up.
        clock_ns: the wall clock for attachments and stamps (ns since the epoch).

    Raises:
        ConfigurationError: a bad name, namespace, domain, mode or endpoint.
    """

    def __init__(
        self,
        node: str = "cas_async",
        *,
        namespace: str = "/",
        domain_id: int = 0,
        distro: str = DISTRO,
        connect: str | Sequence[str] = "tcp/127.0.0.1:7447",
        mode: Literal["client", "peer"] = "client",
        listen: Sequence[str] = (),
        open_timeout: float = 5.0,
        clock_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        self.node = validate_node_name(node)
        self.namespace = validate_namespace(namespace)
        if isinstance(domain_id, bool) or not isinstance(domain_id, int) or not domain_id >= 0:
            raise ConfigurationError(f"ROS domain id must be an int >= 0, got {domain_id!r}")
        if mode not in ("client", "peer"):
            raise ConfigurationError(f"RosLink mode must be 'client' or 'peer', got {mode!r}")
        self.connect = (connect,) if isinstance(connect, str) else tuple(connect)
        for endpoint in (*self.connect, *listen):
            if not _ENDPOINT.fullmatch(endpoint):
                raise ConfigurationError(
                    f"Zenoh endpoint must read PROTOCOL/HOST:PORT (e.g. tcp/192.168.1.20:7447, "
                    f"rmw_zenohd's port), got {endpoint!r}"
                )
        if mode == "client" and not self.connect:
            raise ConfigurationError("a client RosLink needs the router's endpoint (connect=)")
        if not open_timeout > 0:
            raise ConfigurationError(f"open_timeout must be > 0 s, got {open_timeout!r}")
        self.domain_id = domain_id
        self.distro = distro
        self.mode = mode
        self.listen = tuple(listen)
        self.open_timeout = open_timeout
        self._clock_ns = clock_ns
        self._catalog: TypeCatalog | None = None
        self._session: Any = None
        self._state = "unopened"
        self._zid = ""
        self._declared: list[Any] = []  # the node token and the graph subscriber
        self._inbox: ThreadInbox[_Entry] | None = None
        self._next_id = 1
        self._endpoints: list[RosPublisher | RosSubscription] = []
        self._graph: dict[str, GraphEntity] = {}
        self._waiters: list[asyncio.Future[None]] = []
        self.mismatches: list[TypeMismatch] = []
        """Peers' endpoints on our topics with another type or hash, as they were seen
        (the first :data:`MISMATCH_LIMIT`)."""
        self._mismatched: set[TypeMismatch] = set()
        self.mismatches_dropped = 0
        """Mismatches seen past :data:`MISMATCH_LIMIT`, counted only."""
        self.bad_tokens = 0
        """Liveliness tokens under ``@ros2_lv`` that rmw_zenoh would refuse too."""
        self.graph_overflow = 0
        """Tokens of other sessions not kept: the graph held :data:`GRAPH_LIMIT` already."""

    # -- the session -------------------------------------------------------------------

    @property
    def zid(self) -> str:
        """The Zenoh id of this link's session (``""`` until open)."""
        return self._zid

    @property
    def session(self) -> Any:
        """The open ``zenoh.Session``, or ``None``."""
        return self._session

    def clock_ns(self) -> int:
        """Now, by the link's wall clock, in ns since the epoch (attachments, stamps)."""
        return self._clock_ns()

    @property
    def types(self) -> TypeCatalog:
        """The message types of the link's distribution."""
        if self._catalog is None:
            self._catalog = TypeCatalog(self.distro)
        return self._catalog

    async def open(self) -> None:
        """Connects to the router and declares the node.

        Raises:
            ConfigurationError: the ``ros`` extra is missing, the distribution is not
                supported, or no router answered at ``connect`` within ``open_timeout``.
            RobotStateError: the link was opened before.
        """
        if self._state != "unopened":
            raise RobotStateError(f"RosLink {self.node!r} is {self._state}: a link opens once")
        zenoh = import_zenoh()
        types = self.types  # an unsupported distro fails here, before any connection
        self._state = "opening"
        config = loopback_config(mode=self.mode, listen=self.listen, connect=self.connect)
        if self.mode == "client":
            config.insert_json5("connect/timeout_ms", str(int(self.open_timeout * 1000)))
        opening = asyncio.ensure_future(asyncio.to_thread(zenoh.open, config))
        try:
            session = await asyncio.shield(opening)
        except asyncio.CancelledError:
            # The thread cannot be cancelled: close what it opens, or it keeps the process.
            with contextlib.suppress(Exception):
                (await opening).close()
            self._state = "closed"
            raise
        except Exception as exc:  # zenoh.ZError
            self._state = "closed"
            raise ConfigurationError(
                f"no Zenoh router answered at {', '.join(self.connect)} within "
                f"{self.open_timeout:g} s (is rmw_zenohd running there? `ros2 run rmw_zenoh_cpp "
                f"rmw_zenohd` on the robot): {exc}"
            ) from exc
        self._session = session
        self._zid = str(session.zid())
        self._inbox = inbox = ThreadInbox(asyncio.get_running_loop(), self._drain)
        self._state = "open"
        put_kind = zenoh.SampleKind.PUT
        try:
            self._declared.append(
                session.liveliness().declare_subscriber(
                    f"{ADMIN_SPACE}/{self.domain_id}/**",
                    zenoh.handlers.Callback(
                        lambda s: inbox.put((None, str(s.key_expr), s.kind == put_kind)),
                        indirect=False,
                    ),
                    history=True,
                )
            )
            node = self._entity("NN", node_id="0", entity_id="0")
            self._declared.append(session.liveliness().declare_token(node.token()))
        except BaseException:
            self.close()
            raise
        _log.info("ROS node %s on Zenoh session %s (%s)", node.node_fqn, self._zid, types.distro)

    def close(self) -> None:
        """Withdraws every endpoint and token, closes the session; idempotent."""
        if self._state == "closed":
            return
        self._state = "closed"
        for endpoint in self._endpoints:
            endpoint.close()
        declared, self._declared = self._declared, []
        for item in declared:
            with contextlib.suppress(Exception):
                item.undeclare()
        session, self._session = self._session, None
        if session is not None:
            session.close()
        self._wake()

    async def __aenter__(self) -> RosLink:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    def _open_session(self) -> Any:
        if self._state != "open":
            raise RobotStateError(f"RosLink {self.node!r} is {self._state}: open it first")
        return self._session

    def _entity(
        self,
        kind: Kind,
        *,
        node_id: str = "0",
        entity_id: str = "",
        topic: str = "",
        type_name: str = "",
        type_hash: str = "",
        qos: QoS | None = None,
    ) -> GraphEntity:
        if not entity_id:
            entity_id, self._next_id = str(self._next_id), self._next_id + 1
        return GraphEntity(
            domain_id=self.domain_id,
            zid=self._zid,
            node_id=node_id,
            entity_id=entity_id,
            kind=kind,
            enclave="/",
            namespace=self.namespace,
            node=self.node,
            topic=topic,
            type_name=type_name,
            type_hash=type_hash,
            qos=qos,
        )

    # -- endpoints ---------------------------------------------------------------------

    def resolve(self, topic: str) -> str:
        """The fully qualified name of ``topic`` for this node (``cmd_vel`` → ``/ns/cmd_vel``)."""
        return resolve_topic(topic, self.namespace, self.node)

    def publisher(self, topic: str, ros_type: str, *, qos: QoS | None = None) -> RosPublisher:
        """A publisher of ``ros_type`` (``"geometry_msgs/msg/Twist"``) on ``topic``.

        Raises:
            ConfigurationError: a bad topic name, or an unknown type.
            RobotStateError: the link is not open.
        """
        session = self._open_session()
        message, name, qos = self.types.get(ros_type), self.resolve(topic), qos or QoS()
        entity = self._entity(
            "MP", topic=name, type_name=message.dds_name, type_hash=message.type_hash, qos=qos
        )
        zenoh = import_zenoh()
        blocking = qos.reliability == Reliability.RELIABLE and qos.history == History.KEEP_ALL
        publisher = session.declare_publisher(
            data_key(self.domain_id, name, message.dds_name, message.type_hash),
            congestion_control=(
                zenoh.CongestionControl.BLOCK if blocking else zenoh.CongestionControl.DROP
            ),
        )
        token = session.liveliness().declare_token(entity.token())
        endpoint = RosPublisher(entity, message, publisher, token, self._clock_ns)
        self._add(endpoint)
        return endpoint

    def subscribe(
        self,
        topic: str,
        ros_type: str,
        *,
        qos: QoS | None = None,
        max_bytes: int | None = None,
        finite: bool = True,
    ) -> RosSubscription:
        """Messages of ``ros_type`` on ``topic``, as an async iterator of plain values.

        ``qos.depth`` (default 10) messages wait for the reader at most. A sample
        longer than ``max_bytes`` is dropped before it is copied (``oversize``); by
        default the type's own bound (:attr:`RosType.max_size`) or, for a type with
        an unbounded string or sequence, :data:`~cas_async.ros._endpoints.DEFAULT_MAX_BYTES`
        (1 MiB). With ``finite`` (the default), a message holding a NaN or an infinity
        is dropped (``non_finite``); pass ``finite=False`` for types whose infinities
        mean something (REP 117: ``sensor_msgs/msg/LaserScan``'s out-of-range readings).

        Raises:
            ConfigurationError: a bad topic name, an unknown type, a depth < 1, or a
                ``max_bytes`` below 1 or above what Zenoh takes.
            RobotStateError: the link is not open.
        """
        session = self._open_session()
        message, name, qos = self.types.get(ros_type), self.resolve(topic), qos or QoS()
        if qos.depth < 1:
            raise ConfigurationError(f"subscription depth must be >= 1, got {qos.depth}")
        if max_bytes is None:
            max_bytes = message.max_size or DEFAULT_MAX_BYTES
        if (
            isinstance(max_bytes, bool)
            or not isinstance(max_bytes, int)
            or not (1 <= max_bytes <= ZENOH_MESSAGE_LIMIT)
        ):
            raise ConfigurationError(
                f"subscription max_bytes must be an int from 1 to {ZENOH_MESSAGE_LIMIT:,} "
                f"(Zenoh's own limit), got {max_bytes!r}"
            )
        entity = self._entity(
            "MS", topic=name, type_name=message.dds_name, type_hash=message.type_hash, qos=qos
        )
        subscription = RosSubscription(
            entity, message, qos.depth, max_bytes=max_bytes, finite=finite
        )
        inbox = self._inbox
        assert inbox is not None

        def on_sample(sample: Any) -> None:  # on Zenoh's thread
            size = len(sample.payload)
            if not subscription.taken(size):  # before it is copied
                inbox.put((subscription, size, None))
                return
            attachment = sample.attachment
            inbox.put(
                (
                    subscription,
                    sample.payload.to_bytes(),
                    None if attachment is None else attachment.to_bytes(),
                )
            )

        subscriber = session.declare_subscriber(
            data_key(self.domain_id, name, message.dds_name, message.type_hash), on_sample
        )
        subscription.attach(subscriber, session.liveliness().declare_token(entity.token()))
        self._add(subscription)
        return subscription

    def _add(self, endpoint: RosPublisher | RosSubscription) -> None:
        self._endpoints.append(endpoint)
        for peer in list(self._graph.values()):
            self._check_types(peer)

    # -- the graph ---------------------------------------------------------------------

    def graph(self) -> list[GraphEntity]:
        """Every entity with a live token in the domain, this link's own included."""
        return list(self._graph.values())

    def nodes(self) -> list[str]:
        """The nodes of the domain, as ``ros2 node list`` prints them."""
        return sorted({e.node_fqn for e in self._graph.values() if e.kind == "NN"})

    def endpoints(self, topic: str, kind: Kind | None = None) -> list[GraphEntity]:
        """Other sessions' endpoints on ``topic`` (``MP`` publishers, ``MS`` subscriptions)."""
        name = self.resolve(topic)
        return [
            e
            for e in self._graph.values()
            if e.topic == name and e.zid != self._zid and (kind is None or e.kind == kind)
        ]

    async def wait_for(
        self,
        topic: str,
        kind: Kind,
        timeout: float,
        *,
        match: tuple[str, str] | None = None,
    ) -> GraphEntity:
        """The first other endpoint of ``kind`` on ``topic``, once its token is seen.

        With ``match`` (a DDS type name and a type hash), the first whose type and
        hash are these: a stranger's token of another type, seen first, is passed by.

        Raises:
            RosTimeout: none within ``timeout`` seconds (the message lists the nodes seen).
            RobotStateError: the link closed meanwhile.
        """
        name = self.resolve(topic)

        def found_now() -> list[GraphEntity]:
            return [
                entity
                for entity in self.endpoints(name, kind)
                if match is None or (entity.type_name, entity.type_hash) == match
            ]

        try:
            async with asyncio.timeout(timeout):
                while not (found := found_now()):
                    self._open_session()
                    waiter = asyncio.get_running_loop().create_future()
                    self._waiters.append(waiter)
                    await waiter
        except TimeoutError:
            what = "publishes" if kind == "MP" else "subscribes to"
            raise RosTimeout(
                f"no ROS node {what} {name} at {', '.join(self.connect) or 'this session'} "
                f"(domain {self.domain_id}) within {timeout:g} s; nodes seen: "
                f"{', '.join(self.nodes()) or 'none'}"
            ) from None
        return found[0]

    def _wake(self) -> None:
        waiters, self._waiters = self._waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(None)

    def _drain(self, entries: list[_Entry]) -> None:
        changed = False
        for target, key_or_payload, extra in entries:
            if target is not None:
                if isinstance(key_or_payload, int):  # refused for its size, not copied
                    target.refuse_oversize(key_or_payload)
                elif isinstance(key_or_payload, bytes):
                    target.deliver(key_or_payload, extra if isinstance(extra, bytes) else None)
                continue
            key = str(key_or_payload)
            changed = True
            if extra is not True:
                self._graph.pop(key, None)
                continue
            try:
                entity = parse_token(key)
            except ValueError as exc:
                self.bad_tokens += 1
                if is_power_of_ten(self.bad_tokens):
                    _log.warning(
                        "ROS graph: %d token(s) rmw_zenoh would refuse so far; the latest: %s",
                        self.bad_tokens,
                        str(exc)[:300],
                    )
                continue
            full = len(self._graph) >= GRAPH_LIMIT  # ours count too, and always go in
            if full and key not in self._graph and entity.zid != self._zid:
                self.graph_overflow += 1
                continue
            self._graph[key] = entity
            self._check_types(entity)
        if changed:
            self._wake()

    def _check_types(self, peer: GraphEntity) -> None:
        if peer.kind == "NN" or peer.zid == self._zid:
            return
        for endpoint in self._endpoints:
            ours = endpoint.entity
            if ours.topic != peer.topic:
                continue
            if (ours.type_name, ours.type_hash) == (peer.type_name, peer.type_hash):
                continue
            mismatch = TypeMismatch(
                ours.topic,
                f"{ours.type_name}/{ours.type_hash}",
                f"{peer.type_name}/{peer.type_hash}",
                peer,
            )
            if mismatch in self._mismatched:
                continue
            if len(self.mismatches) >= MISMATCH_LIMIT:
                self.mismatches_dropped += 1
            else:
                self.mismatches.append(mismatch)
                self._mismatched.add(mismatch)
            seen = len(self.mismatches) + self.mismatches_dropped
            if is_power_of_ten(seen):
                more = "" if seen == 1 else f" ({seen} mismatched endpoints so far)"
                warnings.warn(f"{mismatch}{more}", RosTypeMismatchWarning, stacklevel=2)

    def __repr__(self) -> str:
        where = f"session {self._zid}" if self._zid else self._state
        return (
            f"RosLink({self.namespace.rstrip('/')}/{self.node}, domain {self.domain_id}, "
            f"{self.distro}, {', '.join(self.connect)}, {where})"
        )
