"""Stack fingerprints: robots may only talk when theirs are equal (DESIGN rule 5).

A fingerprint summarises what a robot's datagrams mean: how many layers its stack
has and, for every message class, its tag, its wire name and the wire schema of
its fields as msgspec describes it (:func:`msgspec.inspect.type_info`): types,
bounds, enum values, nested structs. Two processes that import the same classes
compute the same fingerprint, whatever order they import them in; a module run
with ``python -m pkg.mod`` counts as ``pkg.mod``. A script run by its path names
its classes ``__main__.X``: a process that imports it instead has other tags, so
another fingerprint, unless the classes are named with ``@message(name=...)``.
"""

from __future__ import annotations

import enum
import functools
import zlib
from collections.abc import Iterable
from typing import Any, Final

import msgspec
import msgspec.inspect as mi
import numpy as np

__all__ = ["UnsupportedField", "describe_fingerprint", "schema_text", "stack_fingerprint"]

_CARRIED: Final = (np.ndarray,)
"""Classes a message field may hold beyond what msgspec decodes itself (see _codec)."""


class UnsupportedField(TypeError):
    """A field's type is one no codec of ours can carry."""


def stack_fingerprint(layer_count: int, classes: Iterable[type[msgspec.Struct]]) -> int:
    """A 32-bit summary of a robot's stack: layer count (top byte) and message set.

    The layer count is kept readable so a mismatch can be explained ("4 layers,
    ours has 5"); the message set is a CRC of every message's wire schema.
    """
    text = "\n".join(sorted(schema_text(cls) for cls in classes))
    return ((layer_count & 0xFF) << 24) | (zlib.crc32(text.encode()) & 0xFFFFFF)


def describe_fingerprint(fingerprint: int) -> str:
    """Human-readable form: ``"5 layers, message set 0x1a2b3c"``."""
    return f"{fingerprint >> 24} layers, message set {fingerprint & 0xFFFFFF:#08x}"


@functools.cache
def schema_text(cls: type[msgspec.Struct]) -> str:
    """The canonical text of ``cls``'s wire schema (its tag first).

    Raises:
        UnsupportedField: a field holds a class no codec carries (not a Struct,
            an enum, a builtin type or a numpy array).
        ValueError: a field's bounds leave no value (``ge=2, le=1``).
    """
    info = mi.type_info(cls)
    return _render(info, set())


def _render(node: Any, seen: set[int]) -> str:
    """One node of msgspec's type description, as text; recursive types end in ``...``."""
    if isinstance(node, mi.CustomType):
        if not issubclass(node.cls, _CARRIED):
            raise UnsupportedField(
                f"unsupported field type {node.cls.__qualname__}: use int, float, bool, str, "
                "bytes, None, lists, tuples, dicts, enums, msgspec Structs (messages too) "
                "or numpy.ndarray"
            )
        return node.cls.__name__
    if isinstance(node, mi.StructType):
        if id(node) in seen:
            return f"{node.cls.__name__}..."
        seen = seen | {id(node)}
        fields = ",".join(f"{f.name}:{_field(f, seen)}" for f in node.fields)
        return f"{node.cls.__name__}<{node.tag!r},{int(node.array_like)}>({fields})"
    if isinstance(node, mi.Type):
        parts = [
            f"{name}={_value(getattr(node, name), seen)}"
            for name in node.__struct_fields__
            if getattr(node, name) not in (None, ())
        ]
        text = f"{type(node).__name__.removesuffix('Type')}({','.join(parts)})"
        if _admits_nothing(node):
            raise ValueError(f"the bounds of {text} leave no value")
        return text
    return _value(node, seen)


def _field(field: mi.Field, seen: set[int]) -> str:
    """A struct field's schema; an error about it names the field."""
    try:
        return _render(field.type, seen)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"field {field.name!r}: {exc}") from None


def _admits_nothing(node: Any) -> bool:
    """Bounds no value meets: ``ge=2, le=1``, ``gt=1, lt=1``, ``min_length=3, max_length=2``."""
    if isinstance(node, mi.IntType | mi.FloatType):
        low = node.ge if node.gt is None else node.gt
        high = node.le if node.lt is None else node.lt
        if low is None or high is None:
            return False
        if isinstance(node, mi.IntType):  # whole numbers only
            return low + (node.gt is not None) > high - (node.lt is not None)
        return low > high or (low == high and (node.gt is not None or node.lt is not None))
    shortest, longest = getattr(node, "min_length", None), getattr(node, "max_length", None)
    return shortest is not None and longest is not None and shortest > longest


def _value(value: Any, seen: set[int]) -> str:
    if isinstance(value, mi.Type):
        return _render(value, seen)
    if isinstance(value, tuple):
        return "[" + ",".join(_value(v, seen) for v in value) + "]"
    if isinstance(value, type):
        if issubclass(value, enum.Enum):
            members = ",".join(f"{m.name}={m.value!r}" for m in value)
            return f"{value.__name__}{{{members}}}"
        return value.__name__
    if isinstance(value, mi.Field):
        return f"{value.name}:{_render(value.type, seen)}"
    return repr(value)
