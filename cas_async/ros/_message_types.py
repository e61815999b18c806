"""ROS message types by name: CDR bytes and type hashes from rosbags, plain values in and out.

A :class:`RosType` turns a ``dict`` of plain Python values (numbers, strings,
lists, nested dicts; missing fields are zero or empty, as a freshly constructed
ROS message) into the CDR bytes a ROS 2 node reads, and back. Its ``type_hash``
is the REP-2016 hash (``RIHS01_...``) rmw_zenoh puts in keys and tokens. The
definitions are those of the pinned distribution in rosbags' type store (about
160 common types: ``std_msgs``, ``geometry_msgs``, ``nav_msgs``, ``sensor_msgs``, ...).

Why Jazzy: it is the LTS (supported until 2029) that TurtleBot 4, most ros2_control
robots and Gazebo Harmonic ship with, rmw_zenoh is released for it (binary
attachments since 0.2.4), and it has type hashes (Humble does not: its rmw_zenoh
writes ``TypeHashNotSupported`` instead). Kilted speaks the same format and, for
the types here, the same definitions, so it is accepted too.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import Any, Final

import numpy as np

from .. import ConfigurationError, EncodeError
from ._extra import import_rosbags_typesys
from ._names import dds_type_name, ros_type_name

__all__ = ["DISTRO", "DISTROS", "RosType", "TypeCatalog"]

DISTRO: Final = "jazzy"
"""The pinned distribution: the default, and the one the tests check against."""

DISTROS: Final = ("jazzy", "kilted")
"""The distributions whose rmw_zenoh wire format this package speaks."""

_REFUSED: Final = {
    "humble": "Humble's rmw_zenoh has no type hashes (its keys say TypeHashNotSupported)",
    "iron": "Iron reached its end of life before rmw_zenoh was released for it",
    "rolling": "Rolling moves every month: pin a release",
}

_INTS: Final = {
    "byte": (0, 255),
    "char": (0, 255),
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}
_DTYPES: Final = {
    "bool": np.bool_,
    "byte": np.uint8,
    "char": np.uint8,
    "int8": np.int8,
    "uint8": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}
_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4  # rosbags.interfaces.Nodetype
_SIZES: Final = {
    "bool": 1, "byte": 1, "char": 1, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2,
    "int32": 4, "uint32": 4, "int64": 8, "uint64": 8, "float32": 4, "float64": 8,
}  # fmt: skip
_ENCAPSULATION: Final = 4
"""Bytes of CDR's encapsulation header, before the message."""


def _store_for(distro: str) -> Any:
    typesys = import_rosbags_typesys()
    if distro not in DISTROS:
        why = _REFUSED.get(distro, "no such ROS 2 distribution is known here")
        raise ConfigurationError(
            f"ROS 2 distribution {distro!r} is not supported ({why}); cas_async.ros speaks "
            f"rmw_zenoh as of {' or '.join(DISTROS)}, pinned to {DISTRO}"
        )
    return typesys.get_typestore(getattr(typesys.Stores, f"ROS2_{distro.upper()}"))


class TypeCatalog:
    """The message types of one distribution, resolved by name and cached.

    Raises:
        ConfigurationError: ``distro`` is not one of :data:`DISTROS`, or the ``ros``
            extra is missing.
    """

    def __init__(self, distro: str = DISTRO) -> None:
        self.distro = distro
        self._store = _store_for(distro)
        self._types: dict[str, RosType] = {}

    def get(self, name: str) -> RosType:
        """The type named ``name`` (``pkg/msg/Name``; ``pkg/Name`` is accepted).

        Raises:
            ConfigurationError: no such type in this distribution (close names are
                suggested).
        """
        canonical = ros_type_name(name)
        known = self._types.get(canonical)
        if known is not None:
            return known
        if canonical not in self._store.fielddefs:
            close = difflib.get_close_matches(canonical, list(self._store.fielddefs), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ConfigurationError(f"unknown ROS message type {name!r} in {self.distro}{hint}")
        ros_type = self._types[canonical] = RosType(self._store, canonical)
        return ros_type


class RosType:
    """One message type: its names, its hash, and plain values to and from CDR.

    Attributes:
        name: the ROS name, ``geometry_msgs/msg/Twist``.
        dds_name: the name in keys and tokens, ``geometry_msgs::msg::dds_::Twist_``.
        type_hash: the REP-2016 hash, ``RIHS01_...``.
        max_size: the most bytes a message of the type takes in CDR (with its header
            and the most alignment padding), or ``None`` when it holds an unbounded
            string or sequence (``nav_msgs/msg/Odometry``'s frame ids).
    """

    def __init__(self, store: Any, name: str) -> None:
        self._store = store
        self.name = name
        self.dds_name = dds_type_name(name)
        self.type_hash: str = store.hash_rihs01(name)
        body = self._most_bytes(name)
        self.max_size: int | None = None if body is None else _ENCAPSULATION + body

    def _most_bytes(self, type_name: str) -> int | None:
        """The most bytes of a message's CDR body, padding included; ``None``: no bound."""
        total = 0
        for _, kind in self._store.fielddefs[type_name][1]:
            size = self._field_bytes(kind)
            if size is None:
                return None
            total += size
        return total

    def _field_bytes(self, kind: tuple[Any, Any]) -> int | None:
        node, detail = kind
        node = int(node)
        if node == _BASE:
            primitive, bound = detail
            if primitive in ("string", "wstring"):  # a length, the characters, a NUL
                return (
                    None if not bound else 3 + 4 + bound * (4 if primitive == "wstring" else 1) + 1
                )
            size: int = _SIZES[primitive]
            return size + size - 1  # the value, after at most its alignment's padding
        if node == _NAME:
            return self._most_bytes(detail)
        element, count = detail
        each = self._field_bytes(element)
        if each is None or (node == _SEQUENCE and not count):
            return None
        total: int = count * each + (3 + 4 if node == _SEQUENCE else 0)
        return total

    def encode(self, value: Mapping[str, Any]) -> bytes:
        """The CDR bytes (little-endian, with the 4-byte encapsulation header) of ``value``.

        Raises:
            EncodeError: a field that the type does not have, or a value of the wrong
                kind or out of range; the message names the field's path.
        """
        message = self._build(self.name, value, self.name)
        return bytes(self._store.serialize_cdr(message, self.name))

    def decode(self, data: bytes) -> dict[str, Any]:
        """Plain values (dicts, lists, numbers, strings) from CDR bytes.

        Raises:
            Exception: whatever rosbags raises on malformed bytes (the link drops
                and counts such samples).
        """
        plain: dict[str, Any] = _plain(self._store.deserialize_cdr(data, self.name))
        return plain

    def zero(self) -> dict[str, Any]:
        """The message with every field zero or empty, as plain values."""
        return self.decode(self.encode({}))

    # -- plain values to rosbags' message objects ---------------------------------------

    def _build(self, type_name: str, value: object, path: str) -> Any:
        if not isinstance(value, Mapping):
            raise EncodeError(f"{path}: expected a mapping of fields, got {value!r}")
        _, fields = self._store.fielddefs[type_name]
        names = [name for name, _ in fields]
        unknown = [key for key in value if key not in names]
        if unknown:
            raise EncodeError(
                f"{path}: no field {unknown[0]!r} in {type_name} (fields: {', '.join(names)})"
            )
        built = {
            name: self._field(kind, value.get(name), f"{path}.{name}") for name, kind in fields
        }
        return self._store.types[type_name](**built)

    def _field(self, kind: tuple[Any, Any], value: object, path: str) -> Any:
        node, detail = kind
        node = int(node)
        if node == _BASE:
            return _base(detail[0], value, path)
        if node == _NAME:
            return self._build(detail, {} if value is None else value, path)
        element, size = detail
        items: list[Any]
        if value is None:
            items = []
        elif isinstance(value, str | bytes | Mapping) or not hasattr(value, "__iter__"):
            raise EncodeError(f"{path}: expected a list, got {value!r}")
        else:
            items = list(value)
        if node == _ARRAY:
            if value is None:
                items = [None] * size
            elif len(items) != size:
                raise EncodeError(f"{path}: expected {size} items, got {len(items)}")
        elif size and len(items) > size:
            raise EncodeError(f"{path}: at most {size} items, got {len(items)}")
        converted = [self._field(element, item, f"{path}[{i}]") for i, item in enumerate(items)]
        if int(element[0]) == _BASE and element[1][0] in _DTYPES:
            return np.array(converted, dtype=_DTYPES[element[1][0]])
        return converted


def _base(primitive: str, value: object, path: str) -> Any:
    """A primitive field's value, checked (``None``: the zero of its type)."""
    if primitive == "string" or primitive == "wstring":
        if value is None:
            return ""
        if not isinstance(value, str):
            raise EncodeError(f"{path}: expected a string, got {value!r}")
        return value
    if primitive == "bool":
        if value is None:
            return False
        if not isinstance(value, bool | np.bool_):
            raise EncodeError(f"{path}: expected True or False, got {value!r}")
        return bool(value)
    if primitive in _INTS:
        if value is None:
            return 0
        if isinstance(value, bool) or not isinstance(value, int | np.integer):
            raise EncodeError(f"{path}: expected an integer ({primitive}), got {value!r}")
        low, high = _INTS[primitive]
        if not low <= int(value) <= high:
            raise EncodeError(f"{path}: {value} is out of the range of {primitive}")
        return int(value)
    if value is None:
        return 0.0
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        raise EncodeError(f"{path}: expected a number ({primitive}), got {value!r}")
    number = float(value)
    if primitive == "float32" and math.isfinite(number) and abs(number) > 3.4028234663852886e38:
        raise EncodeError(f"{path}: {value} is out of the range of float32")
    return number


def _plain(message: Any) -> Any:
    """Rosbags' objects as plain values: dataclasses to dicts, arrays to lists."""
    if isinstance(message, np.ndarray):
        return message.tolist()
    if isinstance(message, list):
        return [_plain(item) for item in message]
    fields = getattr(message, "__dataclass_fields__", None)
    if fields is None:
        return message.item() if isinstance(message, np.generic) else message
    return {name: _plain(getattr(message, name)) for name in fields if name != "__msgtype__"}
