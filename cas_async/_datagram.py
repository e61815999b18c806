"""Reading a datagram on the precise path: its structure first, then item by item.

The fast path (see :mod:`cas_async._codec`) parses a datagram in one typed call,
but any datagram it declines comes here to be explained, hostile ones included,
so what is decoded here must cost about what a well-formed datagram of the same
class costs, whatever the bytes claim:

1. msgspec walks the whole datagram without building anything (``Raw``): a
   truncated, malformed or too deeply nested datagram is refused for a few
   nanoseconds per byte, and afterwards every length the datagram claims is
   backed by bytes that are there, so nothing below reserves memory for claims
   (nesting deeper than about 990 levels, Python's recursion limit, is refused);
2. msgpack's unpacker reads the top-level array one item at a time, looking at
   each item's first byte before building it: the eight header items must be
   integers, and an array or a map there is refused as it is, unbuilt;
3. only when the header names a message class of this stack with the right
   number of fields are the fields read, each according to its :class:`FieldPlan`:
   a field the class declares as a scalar (an ``int``, a ``float``, a ``str``...)
   that holds an array or a map is not built (an empty one stands in for it, so
   the class's decoder refuses it with the field's path, as it would the real
   one); a field with a type msgspec checks (``list[int]``...) is checked in C
   first, and refused with msgspec's path without being built; only a field of
   a type that Python code must check (bare ``list``/``dict``, nested messages...)
   is built before it is checked, as it would be when well-formed, and refused if
   it nests deeper than :data:`MAX_NESTING`.

A datagram of 64 KiB of empty arrays, which took the pure-Python unpacker 15 to
23 ms before, is refused after step 1 or 2 in well under a millisecond.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

import msgpack
import msgspec

from ._errors import DecodeError

__all__ = ["CONTAINER", "HEADER_ITEMS", "MAX_NESTING", "FieldPlan", "read_datagram"]

HEADER_ITEMS: Final = 8
"""Fingerprint and type id, then the six header fields."""

MAX_NESTING: Final = 500
"""Levels of arrays and maps one field may nest: what the encoder can send again
(msgpack's packer stops at 511 levels, the datagram's own array included)."""

_WALK: Final = msgspec.msgpack.Decoder(msgspec.Raw)
_MSGSPEC_ERROR: Final = re.compile(r"Expected `(.*?)`, got `(.*?)`(?: - at `(.*)`)?")
_MSGSPEC_BOUND: Final = re.compile(r"Expected `(\w+)` ([<>]=? \S+)(?: - at `(.*)`)?")
_LARGEST_FLOAT: Final = repr(sys.float_info.max)

# First bytes of arrays and maps: fixarray, fixmap, array16/32, map16/32.
_ARRAY_FIRST: Final = frozenset([*range(0x90, 0xA0), 0xDC, 0xDD])
_MAP_FIRST: Final = frozenset([*range(0x80, 0x90), 0xDE, 0xDF])


@dataclass(frozen=True, slots=True)
class FieldPlan:
    """How the precise path reads one field of a message class.

    Attributes:
        path: the field's name in errors, e.g. ``"Meet.speed"``.
        scalar: the field never holds an array or a map.
        check: msgspec's decoder of the field's exact wire type, or ``None`` when
            only Python code can check it.
    """

    path: str
    scalar: bool
    check: Callable[[bytes], Any] | None


_MSGSPEC_NAMES: Final = {"object": "dict", "None": "None"}

_EXPLAINED: Final = 4096
"""Bytes of a field msgspec refused that are built anyway, for the precise error."""


def _refusal(path: str, exc: msgspec.ValidationError) -> DecodeError:
    """The refusal msgspec gave, worded as the converters word theirs (with its path)."""
    text = str(exc)
    bound = _MSGSPEC_BOUND.fullmatch(text)
    if bound is not None:
        kind, limit, at = bound.groups()
        # "Finite" is put to msgspec as the largest floats (see _schema): say finite.
        wanted = f"{kind}(finite)" if limit.endswith(_LARGEST_FLOAT) else f"{kind} {limit}"
        return DecodeError(f"{path}{(at or '$')[1:]}: expected {wanted}", "out_of_range")
    match = _MSGSPEC_ERROR.fullmatch(text)
    if match is None:
        return DecodeError(f"{path}: {text[:200]}", "wrong_type")
    expected, got, at = match.groups()
    got = _MSGSPEC_NAMES.get(got, got)
    return DecodeError(f"{path}{(at or '$')[1:]}: expected {expected}, got {got}", "wrong_type")


class _Container:
    """Stands for an array or a map where a header item should be (it is never built)."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "<array or map>"


CONTAINER: Final = _Container()


def _brief(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}"
    return text if len(text) <= 200 else f"{text[:200]}..."


def _read_field(unpacker: msgpack.Unpacker, data: bytes, plan: FieldPlan) -> Any:
    """The next field of the datagram, read as ``plan`` says (see the module docs)."""
    start = unpacker.tell()
    first = data[start]
    if plan.scalar and (first in _ARRAY_FIRST or first in _MAP_FIRST):
        unpacker.skip()
        return () if first in _ARRAY_FIRST else {}
    if plan.check is not None and not plan.scalar:
        unpacker.skip()
        raw = data[start : unpacker.tell()]
        try:
            plan.check(raw)  # in C, however long: the value is built only if it passes
        except msgspec.ValidationError as exc:
            if len(raw) > _EXPLAINED:  # too costly to build: msgspec's words
                raise _refusal(plan.path, exc) from None
            # Small: built, so that the class's converter refuses it in its own words.
        return msgpack.unpackb(raw, use_list=False, strict_map_key=False)
    value = unpacker.unpack()
    if not plan.scalar and len(data) > MAX_NESTING and _too_deep(value):
        raise DecodeError(
            f"{plan.path}: values nest too deeply (more than {MAX_NESTING} levels)", "wrong_type"
        )
    return value


def _too_deep(value: Any) -> bool:
    """Whether ``value`` nests arrays and maps more than :data:`MAX_NESTING` levels.

    Looked at without recursion, and only in datagrams larger than the limit: a
    level costs at least a byte, so a smaller datagram cannot nest that deep.
    """
    stack = [(value, 0)]
    while stack:
        item, depth = stack.pop()
        kind = type(item)
        if kind is tuple:
            children: Any = item
        elif kind is dict:
            children = item.values()
        else:
            continue
        if depth >= MAX_NESTING:
            return True
        stack.extend((child, depth + 1) for child in children if type(child) in (tuple, dict))
    return False


def read_datagram(
    data: bytes, plan_of: Callable[[Any], tuple[FieldPlan, ...] | None]
) -> tuple[tuple[Any, ...], tuple[Any, ...] | None, int]:
    """The datagram's top-level items, read as the module docs say.

    Args:
        data: the datagram.
        plan_of: for a header's type id, how to read each field of its class, or
            ``None`` for an unknown type: then no field is read.

    Returns:
        ``(header, fields, count)``: the header items (at most ``HEADER_ITEMS``;
        an array or a map there is :data:`CONTAINER`), the fields (arrays
        as tuples), or ``None`` when they were not read (an unknown type, or not
        the number of fields its class has), and the number of top-level items.

    Raises:
        DecodeError: not one msgpack value, or nested too deeply (``malformed``),
            or not an array (``bad_header``).
    """
    try:
        _WALK.decode(data)
    except RecursionError:
        raise DecodeError("not a msgpack datagram: nested too deeply") from None
    except Exception as exc:  # msgspec.DecodeError and its kind: all mean "malformed"
        raise DecodeError(f"not a msgpack datagram: {_brief(exc)}") from None
    if not data or data[0] not in _ARRAY_FIRST:
        raise DecodeError("not a datagram: expected an array with a header", "bad_header")
    size = len(data)
    unpacker = msgpack.Unpacker(
        use_list=False,
        strict_map_key=False,
        max_buffer_size=size,
        max_array_len=size,
        max_map_len=size,
        max_str_len=size,
        max_bin_len=size,
        max_ext_len=size,
    )
    unpacker.feed(data)
    try:
        count = unpacker.read_array_header()
        header: list[Any] = []
        for _ in range(min(count, HEADER_ITEMS)):
            first = data[unpacker.tell()]
            if first in _ARRAY_FIRST or first in _MAP_FIRST:
                unpacker.skip()
                header.append(CONTAINER)
            else:  # an integer, or a scalar that costs what its bytes do
                header.append(unpacker.unpack())
        if count < HEADER_ITEMS:
            return tuple(header), None, count
        plans = plan_of(header[1])
        if plans is None or len(plans) != count - HEADER_ITEMS:
            return tuple(header), None, count
        return tuple(header), tuple(_read_field(unpacker, data, plan) for plan in plans), count
    except DecodeError:
        raise
    except Exception as exc:  # cannot happen after the walk; refused all the same
        raise DecodeError(f"not a msgpack datagram: {_brief(exc)}") from None
