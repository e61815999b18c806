"""Generated encoders and decoders, one pair per message class.

The codec is the hottest code of external traffic, so, like ``dataclasses``, we
write the per-class functions as source once and ``exec`` them. For ``Ping(n: int,
note: str, xs: list[int])`` the pair is, in effect::

    def encode(m, fp, pack):
        return pack((fp, TYPE_ID, m.msg_id, m.msg_type, ..., m.n, m.note, m.xs))

    def decode(t, fp):
        _fp, _tid, mid, mt, rid, src, dst, corr, v0, v1, v2 = t   # arity
        if not (_fp == fp and type(mid) is int and ...): <explain>   # header
        if not (type(v0) is int and type(v1) is str): <slow checks>   # simple fields
        <inline loop: every element of v2 is an int; then list(v2)>   # simple sequences
        m = object.__new__(Ping); m.msg_id = mid; ...; m.n = v0; ...
        return m

Simple checks are inlined; anything else calls the field's converter from
:mod:`cas_async._schema`, which also produces the precise error on the slow path.
Only identifiers (field names, which are Python identifiers, and generated names)
reach the source; names and values travel in the namespace.

When every field has a ``wire`` type (scalars, ``T | None``, IntEnums, and lists
or tuples of those: most messages), a class also gets a *fast pair* built on
msgspec, whose C code checks types while it parses, about three times faster
than unpacking and checking in Python::

    def fast_encode(m, fp, encode):       # None: take the msgpack encoder instead
        n = m.n; note = m.note; xs = m.xs
        if not (type(n) is int and type(note) is str and type(xs) is list or ...):
            return None
        return encode((fp, TYPE_ID, m.msg_id, ..., n, note, xs))

    fast_decode = msgspec Decoder(tuple[int, int, int, MsgType, ..., int, str, list[int]])
    def build(t): <unpack t, make the Ping as decode does>

The fast pair never changes an outcome, only its cost: whatever it declines
(a value msgpack alone would refuse or convert, a datagram msgspec refuses) goes
through the functions above, which make the same message or the precise error.
"""

from __future__ import annotations

import typing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any, Final

import msgspec

from ._errors import DecodeError, StackMismatchError
from ._fingerprint import describe_fingerprint
from ._message import HEADER_FIELDS, Message, MessageSpec, MsgType
from ._schema import FieldType, shown

__all__ = ["HEADER_LEN", "Compiled", "compiled", "undispatchable", "wrong_arity"]

HEADER_LEN: Final = 2 + len(HEADER_FIELDS)
"""Fingerprint and type id, then the header fields."""

_MSG_TYPES: Final = {int(t): t for t in MsgType}
_ID: Final = Annotated[int, msgspec.Meta(ge=0)]  # message ids (and corr_id: 0, not a reply)

Pack = Callable[[Any], bytes]


@dataclass(frozen=True, slots=True)
class Compiled:
    """The generated functions of one message class (the fast ones may be None)."""

    spec: MessageSpec
    encode: Callable[[Message, int, Pack], bytes]
    decode: Callable[[Any, int], Message]
    fast_encode: Callable[[Message, int, Pack], bytes | None] | None = None
    fast_decode: Callable[[bytes], Any] | None = None
    """Parses a whole datagram of this class into a checked tuple (msgspec errors else)."""
    build: Callable[[Any], Message] | None = None
    """Makes the message from what ``fast_decode`` returned."""


def _header_problem(t: Any, fingerprint: int) -> DecodeError | None:
    """Why a datagram's header is refused, checked in a fixed order; None if it is fine.

    The order (shape, fingerprint, type id, header fields) decides the reason a
    datagram is counted under, e.g. another stack's message of an unknown type is a
    ``stack_mismatch``, not an ``unknown_type``.
    """
    if type(t) is not tuple or len(t) < HEADER_LEN:
        return DecodeError("not a datagram: expected an array with a header", "bad_header")
    theirs, tid, sender = t[0], t[1], t[4]
    if type(theirs) is not int or theirs != fingerprint:
        if type(theirs) is not int or type(sender) is not int:
            return DecodeError(f"bad fingerprint {shown(theirs)} in header", "bad_header")
        return StackMismatchError(
            f"datagram from robot {sender} has stack fingerprint {theirs:#010x} "
            f"({describe_fingerprint(theirs)}), ours is {fingerprint:#010x} "
            f"({describe_fingerprint(fingerprint)})",
            sender,
            theirs,
            fingerprint,
        )
    if type(tid) is not int:
        return DecodeError(f"unknown message type id {shown(tid)}", "unknown_type")
    header = t[2:HEADER_LEN]
    if not all(type(v) is int for v in header) or t[3] not in _MSG_TYPES:
        values = ", ".join(map(shown, header))
        return DecodeError(f"bad header ({values}): expected six ints", "bad_header")
    if t[2] < 0 or t[7] < 0:
        return DecodeError(
            f"bad header: msg_id {t[2]} and corr_id {t[7]} must be >= 0", "bad_header"
        )
    return None


def _refused(t: Any, fingerprint: int) -> DecodeError:
    """The error for a header the generated decoder's fast check refused."""
    return _header_problem(t, fingerprint) or DecodeError("bad header", "bad_header")


def undispatchable(t: Any, fingerprint: int) -> DecodeError:
    """Why a datagram has no decoder: a bad header, another stack, or an unknown type."""
    return _header_problem(t, fingerprint) or DecodeError(
        f"unknown message type id {shown(t[1])}", "unknown_type"
    )


def wrong_arity(name: str, expected: int, header: Any, count: int, fingerprint: int) -> DecodeError:
    """Why a datagram of ``count`` items with this ``header`` does not fit class ``name``."""
    problem = _header_problem(header, fingerprint)  # e.g. another stack's version of it
    if problem is not None:
        return problem
    got = count - HEADER_LEN
    return DecodeError(f"{name}: expected {expected} fields, got {got}", "wrong_arity")


def _wrong_arity(name: str, expected: int, t: Any, fingerprint: int) -> DecodeError:
    try:
        return wrong_arity(name, expected, t[:HEADER_LEN], len(t), fingerprint)
    except TypeError:  # not even a sequence
        return DecodeError("not a datagram: expected an array with a header", "bad_header")


def _encoder_source(spec: MessageSpec) -> list[str]:
    values = ", ".join(f"m.{name}" for name in (*HEADER_FIELDS, *spec.field_names))
    return ["def encode(m, fp, pack):", f"    return pack((fp, _tid, {values}))"]


def _decoder_source(spec: MessageSpec, namespace: dict[str, Any]) -> list[str]:
    n = len(spec.field_names)
    unpacked = "".join(f", v{i}" for i in range(n))
    lines = [
        "def decode(t, fp):",
        "    try:",
        f"        _fp, _tid_, mid, mt, rid, src, dst, corr{unpacked} = t",
        "    except (ValueError, TypeError):",
        f"        raise _wrong_arity(_name, {n}, t, fp) from None",
        "    if not (_fp == fp and type(_fp) is int and type(_tid_) is int and type(mid) is int"
        " and type(mt) is int and type(rid) is int and type(src) is int and type(dst) is int"
        " and type(corr) is int and mt in _types and mid >= 0 and corr >= 0):",
        "        raise _refused(t, fp)",
        "    mt = _types[mt]",
    ]
    fast, slow = [], []
    for i, (attr, kind) in enumerate(zip(spec.field_names, spec.field_types, strict=True)):
        namespace[f"_c{i}"] = kind.convert
        namespace[f"_p{i}"] = f"{spec.name}.{attr}"
        call = f"v{i} = _c{i}(v{i}, _p{i})"
        if kind.fast_check is not None:
            fast.append(kind.fast_check.format(v=f"v{i}"))
            slow.append(call)
        elif kind.container is not None and kind.elements is not None:
            namespace[f"_e{i}"] = kind.elements
            namespace[f"_k{i}"] = kind.container
            lines += [
                f"    if type(v{i}) is tuple:",
                f"        for _x in v{i}:",
                f"            if type(_x) is not _e{i}:",
                f"                {call}",  # raises with the element's path
                "                break",
                "        else:",
                f"            v{i} = _k{i}(v{i})" if kind.container is list else "            pass",
                "    else:",
                f"        {call}",
            ]
        else:
            lines.append(f"    {call}")
    if fast:
        lines.append(f"    if not ({' and '.join(fast)}):")
        lines.extend(f"        {call}" for call in slow)
    return lines + _construction(spec)


def _construction(spec: MessageSpec) -> list[str]:
    """Lines making the message from the checked ``mid, mt, ..., v0, v1...``."""
    lines = [
        "    m = _new(_cls)",
        "    m.msg_id = mid; m.msg_type = mt; m.robot_id = rid",
        "    m.src_layer = src; m.dst_layer = dst; m.corr_id = corr",
    ]
    lines.extend(f"    m.{attr} = v{i}" for i, attr in enumerate(spec.field_names))
    if hasattr(spec.cls, "__post_init__"):
        lines += [
            "    try:",
            "        m.__post_init__()",
            "    except Exception as exc:",
            "        raise DecodeError(f'{_name}: rejected by __post_init__: {exc}',"
            " 'wrong_type') from None",
        ]
    lines.append("    return m")
    return lines


def _wire_check(kind: FieldType, v: str, namespace: dict[str, Any], i: int) -> str:
    """An expression true when msgspec may encode ``v``: its type is the declared one.

    msgspec also encodes what msgpack refuses (sets, datetimes, dataclasses...);
    msgpack's encoder turns those into the precise ``EncodeError``, so a value this
    expression does not vouch for goes there. Elements of lists and tuples are not
    looked at (that would cost more than the encoding): a wrong element that msgspec
    can encode reaches the receiver, whose decoder refuses it as ``wrong_type``.
    """
    if kind.fast_check is not None:
        return kind.fast_check.format(v=v)
    if kind.container is not None or typing.get_origin(kind.wire) in (list, tuple):
        return f"(type({v}) is list or type({v}) is tuple)"
    namespace[f"_w{i}"] = kind.wire  # an IntEnum, float | None...
    return f"_vouch({v}, _w{i})"


def _fast_encoder_source(spec: MessageSpec, namespace: dict[str, Any]) -> list[str]:
    names = [f"v{i}" for i in range(len(spec.field_names))]
    checks = [
        _wire_check(kind, v, namespace, i)
        for i, (v, kind) in enumerate(zip(names, spec.field_types, strict=True))
    ]
    header = ", ".join(f"m.{name}" for name in HEADER_FIELDS)
    lines = ["def fast_encode(m, fp, encode):"]
    lines += [f"    {v} = m.{attr}" for v, attr in zip(names, spec.field_names, strict=True)]
    if checks:
        lines += [f"    if not ({' and '.join(checks)}):", "        return None"]
    values = "".join(f", {v}" for v in names)
    lines += [
        "    try:",
        f"        return encode((fp, _tid, {header}{values}))",
        "    except Exception:",  # e.g. a header outside 64 bits: msgpack explains it
        "        return None",
    ]
    return lines


def _build_source(spec: MessageSpec) -> list[str]:
    unpacked = "".join(f", v{i}" for i in range(len(spec.field_names)))
    return [
        "def build(t):",
        f"    _fp, _tid_, mid, mt, rid, src, dst, corr{unpacked} = t",
        *_construction(spec),
    ]


def _vouch(value: Any, wire: Any) -> bool:
    """Whether ``value`` has the ``wire`` type (the rarer field types; see _wire_check)."""
    if typing.get_origin(wire) is Annotated:  # bounds: the receiver checks them
        return _vouch(value, typing.get_args(wire)[0])
    if typing.get_origin(wire) in (list, tuple):
        return type(value) in (list, tuple)
    options = typing.get_args(wire)
    if options:  # T | None
        return any(_vouch(value, option) for option in options)
    return type(value) is wire


def _fast_decoder(spec: MessageSpec) -> Callable[[bytes], Any]:
    fields = tuple(kind.wire for kind in spec.field_types)
    header = (int, int, _ID, MsgType, int, int, int, _ID)
    row: Any = tuple.__class_getitem__((*header, *fields))
    return msgspec.msgpack.Decoder(row).decode


def _compile(spec: MessageSpec) -> Compiled:
    namespace: dict[str, Any] = {
        "_cls": spec.cls,
        "_new": object.__new__,
        "_types": _MSG_TYPES,
        "_tid": spec.type_id,
        "_name": spec.name,
        "_refused": _refused,
        "_wrong_arity": _wrong_arity,
        "DecodeError": DecodeError,
    }
    source = _encoder_source(spec) + _decoder_source(spec, namespace)
    fast = all(kind.wire is not None for kind in spec.field_types)
    if fast:
        namespace["_vouch"] = _vouch
        source += _fast_encoder_source(spec, namespace) + _build_source(spec)
    exec("\n".join(source), namespace)
    if not fast:
        return Compiled(spec, namespace["encode"], namespace["decode"])
    return Compiled(
        spec,
        namespace["encode"],
        namespace["decode"],
        namespace["fast_encode"],
        _fast_decoder(spec),
        namespace["build"],
    )


_cache: dict[MessageSpec, Compiled] = {}


def compiled(spec: MessageSpec) -> Compiled:
    """The generated functions of ``spec``, made once per process."""
    entry = _cache.get(spec)
    if entry is None:
        entry = _cache[spec] = _compile(spec)
    return entry
