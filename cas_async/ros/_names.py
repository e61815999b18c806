"""ROS 2 names and how rmw_zenoh spells them in Zenoh keys.

* A fully qualified topic name (``/robot1/cmd_vel``) comes from a name as a user
  writes it and the node's namespace, as rcl resolves it: ``/x`` is absolute,
  ``x`` is relative to the namespace, ``~/x`` to the node.
* A *mangled* name replaces every ``/`` by ``%`` (liveliness tokens keep one key
  chunk per field); an empty namespace or enclave mangles to ``%``.
* A topic's data key is ``<domain>/<name without outer slashes>/<DDS type>/<hash>``,
  e.g. ``0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...`` (rmw_zenoh's
  ``docs/design.md``, "Topic and Service name mapping").
"""

from __future__ import annotations

import re
from typing import Final

from .. import ConfigurationError

__all__ = [
    "data_key",
    "dds_type_name",
    "demangle",
    "mangle",
    "resolve_topic",
    "ros_name_of_dds",
    "ros_type_name",
    "validate_namespace",
    "validate_node_name",
]

_TOKEN: Final = r"[A-Za-z_][A-Za-z0-9_]*"
_NAMESPACE: Final = re.compile(rf"/|(/{_TOKEN})+")
_NODE: Final = re.compile(_TOKEN)
_RELATIVE: Final = re.compile(rf"{_TOKEN}(/{_TOKEN})*")
_TYPE: Final = re.compile(r"([A-Za-z][A-Za-z0-9_]*)/(?:msg/)?([A-Za-z][A-Za-z0-9_]*)")
_DDS_TYPE: Final = re.compile(r"([A-Za-z][A-Za-z0-9_]*)::msg::dds_::([A-Za-z][A-Za-z0-9_]*)_")


def validate_namespace(namespace: str) -> str:
    """``namespace`` if it is a valid absolute ROS namespace (``/`` or ``/a/b``).

    The empty namespace is the root, ``/``, as rcl (and so rclpy's
    ``Node(name, namespace="")``) takes it.

    Raises:
        ConfigurationError: it is not.
    """
    if namespace == "":
        return "/"
    if not _NAMESPACE.fullmatch(namespace):
        raise ConfigurationError(
            f"ROS namespace must be '/' (or '', the same) or '/word/word...' (letters, digits, "
            f"_; a word does not start with a digit), got {namespace!r}"
        )
    return namespace


def validate_node_name(name: str) -> str:
    """``name`` if it is a valid ROS node name (one word of letters, digits and ``_``).

    Raises:
        ConfigurationError: it is not.
    """
    if not _NODE.fullmatch(name):
        raise ConfigurationError(
            f"ROS node name must be letters, digits and _, not starting with a digit, got {name!r}"
        )
    return name


def resolve_topic(name: str, namespace: str, node: str) -> str:
    """The fully qualified name of topic ``name`` for node ``node`` in ``namespace``.

    Raises:
        ConfigurationError: ``name`` is not a valid ROS topic name.
    """
    if name.startswith("~/"):
        base, relative = f"{namespace.rstrip('/')}/{node}", name[2:]
    elif name.startswith("/"):
        base, relative = "", name[1:]
    else:
        base, relative = namespace.rstrip("/"), name
    if not _RELATIVE.fullmatch(relative):
        raise ConfigurationError(
            f"ROS topic name must be words of letters, digits and _ separated by '/' "
            f"(absolute '/x', relative 'x' or private '~/x'), got {name!r}"
        )
    return f"{base}/{relative}"


def mangle(name: str) -> str:
    """``name`` with every ``/`` replaced by ``%`` (rmw_zenoh's ``mangle_name``)."""
    return name.replace("/", "%")


def demangle(name: str) -> str:
    """``name`` with every ``%`` replaced by ``/`` (rmw_zenoh's ``demangle_name``)."""
    return name.replace("%", "/")


def ros_type_name(name: str) -> str:
    """The canonical ROS name of a message type: ``pkg/msg/Name`` (``pkg/Name`` is accepted).

    Raises:
        ConfigurationError: ``name`` is no message type name.
    """
    match = _TYPE.fullmatch(name)
    if match is None:
        raise ConfigurationError(
            f"a ROS message type is named 'package/msg/Name' (e.g. 'geometry_msgs/msg/Twist'), "
            f"got {name!r}"
        )
    return f"{match[1]}/msg/{match[2]}"


def dds_type_name(ros_type: str) -> str:
    """The DDS name rmw_zenoh uses in keys: ``geometry_msgs::msg::dds_::Twist_``."""
    package, _, name = ros_type_name(ros_type).split("/")
    return f"{package}::msg::dds_::{name}_"


def ros_name_of_dds(dds_type: str) -> str | None:
    """``pkg/msg/Name`` for a DDS message type name, ``None`` if it is not one."""
    match = _DDS_TYPE.fullmatch(dds_type)
    return None if match is None else f"{match[1]}/msg/{match[2]}"


def data_key(domain_id: int, topic: str, dds_type: str, type_hash: str) -> str:
    """The Zenoh key a topic's samples are put under (outer slashes of the name stripped)."""
    return f"{domain_id}/{topic.strip('/')}/{dds_type}/{type_hash}"
