"""The ROS graph as rmw_zenoh sees it: one liveliness token per node and per entity.

Formats (rmw_zenoh ``docs/design.md``, "Graph Cache"; ``liveliness_utils.cpp``)::

    @ros2_lv/<domain>/<zid>/<node id>/<node id>/NN/<enclave>/<namespace>/<node>
    @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<MP|MS|SS|SC>/<enclave>/<namespace>/<node>/
        <topic>/<DDS type>/<type hash>/<qos>

Enclave, namespace and topic are mangled (``/`` → ``%``, empty → ``%``); ``<zid>`` is
the Zenoh session id. :func:`parse_token` reads a token the way rmw_zenoh's graph
cache does (``Entity::make(keyexpr)``): what it refuses, rmw_zenoh refuses too, and
a node that refuses a token does not show the entity (``ros2 node list`` misses it).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Final, Literal

from ._names import demangle, mangle
from ._qos import QoS

__all__ = ["ADMIN_SPACE", "GraphEntity", "Kind", "entity_gid", "parse_token"]

ADMIN_SPACE: Final = "@ros2_lv"
"""The hermetic Zenoh namespace of rmw_zenoh's liveliness tokens."""

Kind = Literal["NN", "MP", "MS", "SS", "SC"]
_KINDS: Final[frozenset[str]] = frozenset(("NN", "MP", "MS", "SS", "SC"))
_NODE_PARTS: Final = 9  # up to the node name
_ENTITY_PARTS: Final = 13  # up to the QoS


@dataclass(frozen=True, slots=True)
class GraphEntity:
    """A node or a topic/service endpoint of the ROS graph, as its token says.

    Attributes:
        domain_id: the ROS domain (``ROS_DOMAIN_ID``).
        zid: the Zenoh session (one per ROS context) it lives in.
        node_id: the node's id within the context.
        entity_id: the entity's id within the context (the node's own for ``NN``).
        kind: ``NN`` node, ``MP`` publisher, ``MS`` subscription, ``SS`` service
            server, ``SC`` service client.
        enclave: the SROS enclave (``/`` when none).
        namespace: the node's namespace (``/`` when none).
        node: the node's name.
        topic: the fully qualified topic or service name (``""`` for a node).
        type_name: the DDS type name, e.g. ``geometry_msgs::msg::dds_::Twist_``.
        type_hash: the type hash, e.g. ``RIHS01_9c45...``.
        qos: the endpoint's QoS (``None`` for a node).
    """

    domain_id: int
    zid: str
    node_id: str
    entity_id: str
    kind: Kind
    enclave: str = "/"
    namespace: str = "/"
    node: str = ""
    topic: str = ""
    type_name: str = ""
    type_hash: str = ""
    qos: QoS | None = None

    @property
    def node_fqn(self) -> str:
        """The node's fully qualified name, as ``ros2 node list`` prints it."""
        return f"{self.namespace.rstrip('/')}/{self.node}"

    def token(self) -> str:
        """The liveliness key expression that declares this entity."""
        parts = [
            ADMIN_SPACE,
            str(self.domain_id),
            self.zid,
            self.node_id,
            self.entity_id,
            self.kind,
            _mangle_root(self.enclave),
            _mangle_root(self.namespace),
            mangle(self.node),
        ]
        if self.kind != "NN":
            qos = self.qos if self.qos is not None else QoS()
            parts += [mangle(self.topic), mangle(self.type_name), self.type_hash, qos.to_key()]
        return "/".join(parts)


def _mangle_root(name: str) -> str:
    """A namespace or enclave mangled; ``/`` (or empty: none) is ``%``."""
    return mangle(name) if name else "%"


def parse_token(key: str) -> GraphEntity:
    """The entity a liveliness token declares, read as rmw_zenoh's ``Entity::make`` reads it.

    Raises:
        ValueError: rmw_zenoh would refuse the token too (fewer than 9 chunks, an
            empty chunk, another admin space, an unknown entity kind, an endpoint
            without its topic, type, hash and QoS, or a QoS it cannot read); the
            message says which.
    """
    parts = key.split("/")
    if len(parts) < _NODE_PARTS:
        raise ValueError(f"liveliness token with {len(parts)}/{_NODE_PARTS} parts: {key}")
    if any(not part for part in parts):
        raise ValueError(f"liveliness token with empty parts: {key}")
    if parts[0] != ADMIN_SPACE:
        raise ValueError(f"liveliness token outside {ADMIN_SPACE}: {key}")
    kind = parts[5]
    if kind not in _KINDS:
        raise ValueError(f"liveliness token with invalid entity {kind}: {key}")
    if not (parts[1].isascii() and parts[1].isdigit()):
        raise ValueError(f"liveliness token with invalid domain id {parts[1]!r}: {key}")
    entity = GraphEntity(
        domain_id=int(parts[1]),
        zid=parts[2],
        node_id=parts[3],
        entity_id=parts[4],
        kind=kind,  # type: ignore[arg-type]  # one of _KINDS, checked above
        enclave=demangle(parts[6]),
        namespace=demangle(parts[7]),
        node=demangle(parts[8]),
    )
    if kind == "NN":
        return entity
    if len(parts) < _ENTITY_PARTS:
        raise ValueError(f"liveliness token for a {kind} without its topic, type and QoS: {key}")
    return GraphEntity(
        domain_id=entity.domain_id,
        zid=entity.zid,
        node_id=entity.node_id,
        entity_id=entity.entity_id,
        kind=entity.kind,
        enclave=entity.enclave,
        namespace=entity.namespace,
        node=entity.node,
        topic=demangle(parts[9]),
        type_name=demangle(parts[10]),
        type_hash=demangle(parts[11]),
        qos=QoS.from_key(parts[12]),
    )


def entity_gid(token: str) -> bytes:
    """The 16-byte GID an entity puts in its attachments: a hash of its token.

    rmw_zenoh hashes the token with XXH3-128; any stable 16 bytes unique to the
    entity serve a subscriber (it tells publishers apart and counts lost samples
    by GID), and BLAKE2b needs no extra package. ``ros2 topic info -v`` shows
    rmw_zenoh's hash of our token, which therefore differs from the GID in our
    samples' ``message_info``.
    """
    return hashlib.blake2b(token.encode(), digest_size=16).digest()
