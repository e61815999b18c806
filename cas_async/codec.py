"""The msgpack wire format of external messages, with limits and strict decoding.

A datagram is one msgpack array::

    [fingerprint, type_id, msg_id, msg_type, robot_id, src_layer, dst_layer, corr_id, *fields]

Encoding reads the header and fields with one ``operator.attrgetter`` call and packs
the tuple with a reused ``msgpack.Packer``. Decoding unpacks (arrays as tuples),
checks the header and then runs a decoder generated once per message class, which
checks simple fields with inlined ``type(v) is int`` tests and only calls the
slower converters of :mod:`cas_async.schema` when a field needs it. Every problem
with untrusted bytes raises :class:`~cas_async.errors.DecodeError`; nothing is
ever unpickled.
"""

from __future__ import annotations

import operator
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Final

import msgpack
import numpy as np

from .errors import DecodeError, EncodeError, StackMismatchError
from .message import HEADER_FIELDS, Message, MessageSpec, MsgType, nested_to_wire, spec_of
from .schema import ndarray_to_wire

__all__ = ["DEFAULT_MAX_DATAGRAM", "Codec", "describe_fingerprint", "stack_fingerprint"]

DEFAULT_MAX_DATAGRAM: Final = 64 * 1024
"""Largest datagram encoded or accepted, in bytes, unless configured otherwise."""

_HEADER_LEN: Final = 2 + len(HEADER_FIELDS)  # fingerprint and type id, then the header
_MSG_TYPES: Final = {int(t): t for t in MsgType}


def stack_fingerprint(layer_count: int, specs: Mapping[int, MessageSpec]) -> int:
    """A 32-bit summary of a robot's stack: layer count (top byte) and message set.

    Robots may only talk when their fingerprints are equal (DESIGN rule 5).
    """
    text = "\n".join(spec.schema for _, spec in sorted(specs.items()))
    return ((layer_count & 0xFF) << 24) | (zlib.crc32(text.encode()) & 0xFFFFFF)


def describe_fingerprint(fingerprint: int) -> str:
    """Human-readable form: ``"5 layers, message set 0x1a2b3c"``."""
    return f"{fingerprint >> 24} layers, message set {fingerprint & 0xFFFFFF:#08x}"


def _encode_default(obj: Any) -> Any:
    """Packs what msgpack cannot: nested messages, numpy arrays and scalars."""
    if isinstance(obj, Message):
        return nested_to_wire(obj)
    if isinstance(obj, np.ndarray):
        return ndarray_to_wire(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"cannot encode a value of type {type(obj).__qualname__}")


@dataclass(frozen=True, slots=True)
class _Compiled:
    """The generated per-class encoder getter and decoder."""

    spec: MessageSpec
    arity: int
    getter: Callable[[Message], tuple[Any, ...]]
    decode: Callable[[tuple[Any, ...]], Message]


def _bad_header(t: tuple[Any, ...]) -> None:
    raise DecodeError(f"bad header {t[2:_HEADER_LEN]!r}: expected six ints", "bad_header")


def _compile(spec: MessageSpec) -> _Compiled:
    """Generates the decoder of one message class (see the module docstring)."""
    n = len(spec.field_names)
    names = [f"v{i}" for i in range(n)]
    namespace: dict[str, Any] = {
        "_cls": spec.cls,
        "_new": object.__new__,
        "_types": _MSG_TYPES,
        "_bad_header": _bad_header,
        "DecodeError": DecodeError,
        "_name": spec.name,
    }
    fast = []
    lines = [
        "def decode(t):",
        f"    _fp, _tid, mid, mt, rid, src, dst, corr{''.join(', ' + v for v in names)} = t",
        "    if not (type(mid) is int and type(mt) is int and type(rid) is int"
        " and type(src) is int and type(dst) is int and type(corr) is int):",
        "        _bad_header(t)",
        "    mt = _types.get(mt)",
        "    if mt is None:",
        "        _bad_header(t)",
    ]
    slow = []
    for i, (attr, kind) in enumerate(zip(spec.field_names, spec.field_types, strict=True)):
        namespace[f"_c{i}"] = kind.convert
        call = f"v{i} = _c{i}(v{i}, {spec.name + '.' + attr!r})"
        if kind.fast_check is not None:
            fast.append(kind.fast_check.format(v=f"v{i}"))
            slow.append(call)
        else:
            lines.append(f"    {call}")
    if fast:
        lines.append(f"    if not ({' and '.join(fast)}):")
        lines.extend(f"        {call}" for call in slow)
    lines.append("    m = _new(_cls)")
    lines.append(
        "    m.msg_id = mid; m.msg_type = mt; m.robot_id = rid; "
        "m.src_layer = src; m.dst_layer = dst; m.corr_id = corr"
    )
    lines.extend(f"    m.{attr} = v{i}" for i, attr in enumerate(spec.field_names))
    if hasattr(spec.cls, "__post_init__"):
        lines.extend(
            [
                "    try:",
                "        m.__post_init__()",
                "    except Exception as exc:",
                "        raise DecodeError(f'{_name}: rejected by __post_init__: {exc}',"
                " 'wrong_type') from None",
            ]
        )
    lines.append("    return m")
    exec("\n".join(lines), namespace)
    getter = operator.attrgetter(*HEADER_FIELDS, *spec.field_names)
    return _Compiled(spec, _HEADER_LEN + n, getter, namespace["decode"])


_compiled: dict[MessageSpec, _Compiled] = {}


def _compiled_for(spec: MessageSpec) -> _Compiled:
    entry = _compiled.get(spec)
    if entry is None:
        entry = _compiled[spec] = _compile(spec)
    return entry


class Codec:
    """Encodes and decodes the external messages of one robot.

    Args:
        specs: the message types this robot accepts, by type id.
        fingerprint: this robot's stack fingerprint (see :func:`stack_fingerprint`).
        max_size: largest datagram, in bytes, encoded or accepted.
    """

    __slots__ = ("_by_class", "_by_id", "_pack", "fingerprint", "max_size")

    def __init__(
        self,
        specs: Mapping[int, MessageSpec],
        fingerprint: int,
        max_size: int = DEFAULT_MAX_DATAGRAM,
    ) -> None:
        if max_size < 64:
            raise ValueError(f"max_size must be at least 64 bytes, got {max_size}")
        self.fingerprint = fingerprint
        self.max_size = max_size
        self._by_id = {tid: _compiled_for(spec) for tid, spec in specs.items()}
        self._by_class = {c.spec.cls: c for c in self._by_id.values()}
        self._pack = msgpack.Packer(default=_encode_default, use_bin_type=True).pack

    def encode(self, msg: Message) -> bytes:
        """The datagram for ``msg``.

        Raises:
            EncodeError: a field holds a value msgpack cannot carry, the message type
                is not accepted by this robot, or the datagram exceeds ``max_size``.
        """
        entry = self._by_class.get(type(msg))
        if entry is None:
            spec = spec_of(type(msg))  # raises when @message was forgotten
            raise EncodeError(f"{spec.name} is not among the messages this robot's stack accepts")
        try:
            data: bytes = self._pack((self.fingerprint, entry.spec.type_id, *entry.getter(msg)))
        except (TypeError, ValueError, OverflowError) as exc:
            raise EncodeError(
                f"cannot encode {entry.spec.name}: {_which_field(msg, entry)}{exc}"
            ) from exc
        if len(data) > self.max_size:
            raise EncodeError(
                f"{entry.spec.name} encodes to {len(data)} bytes, "
                f"above the limit of {self.max_size}"
            )
        return data

    def decode(self, data: bytes) -> Message:
        """The message in ``data``; ``DecodeError`` for anything malformed.

        Raises:
            StackMismatchError: well-formed, but from a robot with another stack.
            DecodeError: anything else wrong, with a ``reason`` for counters.
        """
        if len(data) > self.max_size:
            raise DecodeError(f"{len(data)} bytes, above the limit of {self.max_size}", "oversize")
        try:
            t = msgpack.unpackb(data, use_list=False, raw=False, strict_map_key=False)
        except Exception as exc:  # the unpacker raises many types; all mean "malformed"
            raise DecodeError(f"not a msgpack datagram: {type(exc).__name__}: {exc}") from None
        if type(t) is not tuple or len(t) < _HEADER_LEN:
            raise DecodeError("not a datagram: expected an array with a header", "bad_header")
        fingerprint, tid = t[0], t[1]
        if type(fingerprint) is not int or fingerprint != self.fingerprint:
            if type(fingerprint) is int and type(t[4]) is int:
                raise StackMismatchError(
                    f"datagram from robot {t[4]} has stack fingerprint {fingerprint:#010x} "
                    f"({describe_fingerprint(fingerprint)}), ours is {self.fingerprint:#010x} "
                    f"({describe_fingerprint(self.fingerprint)})",
                    t[4],
                    fingerprint,
                    self.fingerprint,
                )
            raise DecodeError("bad fingerprint in header", "bad_header")
        entry = self._by_id.get(tid) if type(tid) is int else None
        if entry is None:
            raise DecodeError(f"unknown message type id {tid!r}", "unknown_type")
        if len(t) != entry.arity:
            raise DecodeError(
                f"{entry.spec.name}: expected {entry.arity - _HEADER_LEN} fields, "
                f"got {len(t) - _HEADER_LEN}",
                "wrong_arity",
            )
        try:
            return entry.decode(t)
        except RecursionError:  # bare list/dict fields or recursive messages, nested deeply
            raise DecodeError(f"{entry.spec.name}: values nest too deeply", "wrong_type") from None


def _which_field(msg: Message, entry: _Compiled) -> str:
    """Names the first field msgpack refuses, to make encode errors actionable."""
    pack = msgpack.Packer(default=_encode_default, use_bin_type=True).pack
    for attr in entry.spec.field_names:
        try:
            pack(getattr(msg, attr))
        except (TypeError, ValueError, OverflowError):
            return f"field {attr!r}: "
    return ""
