"""The wire format of external messages, with limits and strict decoding.

A datagram is the sender's stack fingerprint (4 bytes, big-endian), then the
message as one msgpack array, as msgspec encodes a :class:`~cas_async.Message`::

    fingerprint | [tag, *fields, msg_type, msg_id, robot_id, src_layer, dst_layer, corr_id]

What stays ours is small: the fingerprint prefix and the size limit, both checked
before anything is decoded, and the stable drop reasons users monitor
(:attr:`DecodeError.REASONS <cas_async.DecodeError>`), mapped from msgspec's
errors. The rest is msgspec's: one ``Decoder`` over the union of a stack's
messages parses the array in C, the tag picking the class, every field checked
against its declared type and bounds. Every problem with untrusted bytes raises
:class:`~cas_async._errors.DecodeError`; nothing is ever unpickled.

Decoding is bounded whatever a datagram claims: msgspec checks every length
against the bytes present before it builds anything, so a hostile datagram costs
about what a well-formed one of its size does, and memory is bounded by
:attr:`Codec.max_decode_bytes`.
"""

from __future__ import annotations

import re
import sys
import threading
from collections.abc import Iterable
from typing import Any, Final, Union, get_origin

import msgspec
import msgspec.inspect as mi
import numpy as np

from .._errors import DecodeError, EncodeError, MessageDefinitionError, StackMismatchError
from ._fingerprint import describe_fingerprint, stack_fingerprint
from ._message import HEADER_FIELDS, Message, all_messages, wire_name

__all__ = ["DEFAULT_MAX_DATAGRAM", "MIN_DATAGRAM", "PREFIX", "Codec"]

DEFAULT_MAX_DATAGRAM: Final = 64 * 1024
"""Largest datagram encoded or accepted, in bytes, unless configured otherwise."""

MIN_DATAGRAM: Final = 64
"""Smallest datagram limit accepted: below it not even a header with a small field fits."""

PREFIX: Final = 4
"""Bytes of the fingerprint that begins every datagram."""

_BYTES_PER_BYTE: Final = 128
"""Most bytes of Python objects one datagram byte decodes into, with margin, for the
wire's own values: worst cases measured with tracemalloc (tests/test_decode_limits.py)
are empty maps in a bare ``list`` field (one byte each, a dict each, about 113 B/B) and
arrays nested in arrays. A struct adds what :func:`_struct_cost` says (see there)."""

_POINTER: Final = 8
"""Bytes of the slot that holds one decoded struct in its container."""
_GC_HEADER: Final = 16
"""Bytes the cyclic collector adds to each struct it tracks (not in ``__basicsize__``)."""

_DECODE_OVERHEAD: Final = 256 * 1024
"""Fixed allowance of a decode: decoder state, one error message."""

_SHARED_CODECS: Final = 32
"""Stacks whose codec a thread keeps (:meth:`Codec.shared`)."""

_per_thread: Final = threading.local()

_PATH: Final = re.compile(r" - at (`key` in )?`\$\[(\d+)\]([^`]*)`$")
_FINITE: Final = re.compile(
    "`float` (>= |<= )" + re.escape(repr(sys.float_info.max)).replace("1", "-?1", 1)
)
"""How msgspec words a bound of :data:`~cas_async.Finite` (said "a finite float" instead)."""
_BOUND: Final = re.compile(
    r"^Expected `\w+` (of length )?(>=|<=|>|<) |^Expected `\w+` (matching regex|that's a multiple)"
)
"""How msgspec words the refusal of a bound (a range, a length, a pattern): ``out_of_range``."""
_ARITY: Final = re.compile(r"^Expected `array` of (at least |at most )?length \d+, got \d+$")
_ARRAY_HEADS: Final = frozenset(range(0x90, 0xA0)) | {0xDC, 0xDD}
"""First bytes of a msgpack array: what follows a fingerprint in any stack's datagram."""
_RAW_ITEMS: Final = msgspec.msgpack.Decoder(list[msgspec.Raw])
_NUMERIC_KINDS: Final = frozenset("biufc")
_DTYPE_TEXT: Final = re.compile(r"[<>|=]?[biufc][0-9]{1,2}")
_MAX_NDIM: Final = 32


class Codec:
    """Encodes and decodes the external messages of one robot's stack.

    Decoding a datagram never allocates more than :attr:`max_decode_bytes` bytes,
    whatever it claims (arrays or maps of 2**32 items, strings of 4 GiB, arrays
    nested 1024 deep, numpy arrays of 10**9 elements)::

        max_decode_bytes = per_byte * max_size + 256 KiB

    where ``per_byte`` is 128 for the wire's own values, or more for a stack whose
    structs are built from fewer bytes than they take (see :func:`_struct_cost`).

    Args:
        layers: the number of layers of the stack.
        messages: the message classes the stack uses (default: every one defined).
        max_size: largest datagram, in bytes, encoded or accepted.

    Raises:
        MessageDefinitionError: a class is not a message, or two have one tag.
        ValueError: ``max_size`` is below :data:`MIN_DATAGRAM`.
    """

    passes_objects = False
    """Receivers get bytes, never the objects sent."""

    __slots__ = (
        "_by_tag",
        "_classes",
        "_decode",
        "_encode",
        "_per_byte",
        "_prefix",
        "fingerprint",
        "max_size",
    )

    def __init__(
        self,
        layers: int,
        messages: Iterable[type[Message]] | None = None,
        max_size: int = DEFAULT_MAX_DATAGRAM,
    ) -> None:
        if max_size < MIN_DATAGRAM:
            raise ValueError(f"max_size must be at least {MIN_DATAGRAM} bytes, got {max_size}")
        classes = all_messages() if messages is None else tuple(dict.fromkeys(messages))
        self._by_tag = _by_tag(classes)
        self._classes = frozenset(classes)
        self.fingerprint = stack_fingerprint(layers, classes)
        self.max_size = max_size
        self._prefix = self.fingerprint.to_bytes(PREFIX, "big")
        self._per_byte = max([_BYTES_PER_BYTE, *map(_struct_cost, _structs(classes))])
        if classes:
            union: Any = Union[tuple(classes)]  # noqa: UP007 - a union made at run time
            self._decode = msgspec.msgpack.Decoder(union, dec_hook=_decode_custom).decode
        else:
            self._decode = _no_message
        self._encode = msgspec.msgpack.Encoder(enc_hook=_encode_custom).encode

    @classmethod
    def for_stack(
        cls,
        layers: int,
        messages: Iterable[type[Message]] | None = None,
        max_size: int = DEFAULT_MAX_DATAGRAM,
    ) -> Codec:
        """The codec of a robot with ``layers`` layers and these messages (default: all).

        What a robot so made encodes, this codec encodes byte for byte: a test or a
        transport author can craft datagrams a robot of that stack accepts.
        """
        return cls(layers, messages, max_size)

    @classmethod
    def shared(
        cls,
        layers: int,
        messages: tuple[type[Message], ...] | None,
        max_size: int = DEFAULT_MAX_DATAGRAM,
    ) -> Codec:
        """:meth:`for_stack`, made once per thread for robots of one stack to share.

        A codec holds nothing of a robot's, and making one builds a decoder: ten
        thousand robots of one stack share one. Shared within a thread only.
        """
        classes = all_messages() if messages is None else messages
        key = (layers, classes, max_size)
        codecs: dict[Any, Codec] | None = getattr(_per_thread, "codecs", None)
        if codecs is None:
            codecs = _per_thread.codecs = {}
        codec = codecs.get(key)
        if codec is None:
            codec = cls(layers, classes, max_size)
            if len(codecs) >= _SHARED_CODECS:  # bounded: tests make stacks by the hundred
                del codecs[next(iter(codecs))]
            codecs[key] = codec
        return codec

    @property
    def message_classes(self) -> frozenset[type[Message]]:
        """The message classes this codec carries."""
        return self._classes

    @property
    def max_decode_bytes(self) -> int:
        """Most bytes decoding one datagram allocates at once (see the class docs)."""
        return self._per_byte * self.max_size + _DECODE_OVERHEAD

    def encode(self, msg: Message) -> bytes:
        """The datagram for ``msg``.

        Raises:
            EncodeError: a field holds a value msgpack cannot carry, the message type
                is not accepted by this robot, or the datagram exceeds ``max_size``.
        """
        if type(msg) not in self._classes:
            raise EncodeError(self._not_ours(msg))
        try:
            data = self._prefix + self._encode(msg)
        except (TypeError, ValueError, OverflowError, RecursionError, msgspec.EncodeError) as exc:
            raise EncodeError(f"cannot encode {_named(msg)}: {_which_field(msg)}{exc}") from exc
        if len(data) > self.max_size:
            raise EncodeError(
                f"{_named(msg)} encodes to {len(data)} bytes, above the limit of {self.max_size}"
            )
        return data

    def decode(self, data: bytes) -> Message:
        """The message in ``data``; ``DecodeError`` for anything malformed.

        Raises:
            StackMismatchError: a datagram from a robot with another stack.
            DecodeError: anything else wrong, with a ``reason`` for counters.
        """
        # bytes, bytearray and memoryview all slice and compare alike: no conversion.
        if data[:PREFIX] != self._prefix or len(data) > self.max_size:
            raise self._refused(data)
        try:
            msg: Message = self._decode(data[PREFIX:])
        except DecodeError:
            raise
        except msgspec.ValidationError as exc:
            raise self._invalid(str(exc), data) from None
        except msgspec.DecodeError as exc:
            raise DecodeError(f"malformed: {exc}", "malformed") from None
        except UnicodeDecodeError as exc:  # msgspec before 0.23 raised it for a str of bad UTF-8
            raise DecodeError(f"malformed: a str is not UTF-8: {exc.reason}", "malformed") from None
        except RecursionError:  # bare list/dict fields or recursive messages, nested deeply
            raise DecodeError("values nest too deeply", "wrong_type") from None
        except Exception as exc:  # a __post_init__ or hook's oversight must not reach a robot
            raise DecodeError(f"cannot decode: {_brief_error(exc)}", "wrong_type") from None
        if msg.msg_id > 0:
            return msg
        # The header is missing: trailing fields take their defaults when absent.
        raise DecodeError(f"bad header: {type(msg).__name__} has no message id", "bad_header")

    def _not_ours(self, msg: object) -> str:
        if not isinstance(msg, Message):
            return f"{type(msg).__qualname__} is not a message (a subclass of cas_async.Message)"
        return f"{wire_name(type(msg))} is not among the messages this robot's stack accepts"

    def _refused(self, data: bytes) -> DecodeError:
        """Why a datagram is refused before decoding: too large, another stack's, or garbage."""
        if len(data) > self.max_size:
            return DecodeError(f"{len(data)} bytes, above the limit of {self.max_size}", "oversize")
        if len(data) <= PREFIX or data[PREFIX] not in _ARRAY_HEADS:
            return DecodeError(f"not a datagram ({len(data)} bytes)", "malformed")
        theirs = int.from_bytes(data[:PREFIX], "big")
        ours = self.fingerprint
        return StackMismatchError(
            f"datagram of stack fingerprint {theirs:#010x} ({describe_fingerprint(theirs)}), "
            f"ours is {ours:#010x} ({describe_fingerprint(ours)})",
            theirs,
            ours,
        )

    def _invalid(self, text: str, data: bytes) -> DecodeError:
        """Msgspec's refusal as a ``DecodeError``: the field named, the reason classified."""
        found = _PATH.search(text)
        if found is None:  # about the array itself (its length), or not an array
            try:
                items = _RAW_ITEMS.decode(data[PREFIX:])
            except msgspec.ValidationError:
                return DecodeError(f"not a datagram: {text}", "bad_header")
            except (msgspec.DecodeError, RecursionError):  # it claims more than there is
                return DecodeError(f"malformed: {text}", "malformed")
            cls = self._class_of(data)
            if cls is None:  # pragma: no cover - msgspec read its tag
                return DecodeError(f"not a datagram: {text}", "bad_header")
            if _ARITY.match(text) is None:  # the class refused its values: its __post_init__
                return DecodeError(f"{cls.__name__}: {text}", "wrong_type")
            fields = len(cls.__struct_fields__)
            return DecodeError(
                f"{cls.__name__}: {text}: {len(items)} items for the tag, "
                f"{fields - len(HEADER_FIELDS)} fields and {len(HEADER_FIELDS)} header values",
                "wrong_arity",
            )
        index = int(found.group(2))
        if index == 0:
            return DecodeError(f"unknown message tag: {text}", "unknown_type")
        cls = self._class_of(data)
        if cls is None:  # pragma: no cover - msgspec read a tag it knows to get here
            return DecodeError(text, "wrong_type")
        names = cls.__struct_fields__
        field = names[index - 1] if index - 1 < len(names) else "?"
        problem = _FINITE.sub("a finite `float`", text[: found.start()])
        key = " key" if found.group(1) else ""  # a dict's key, not its value
        where = f"{cls.__name__}.{field}{found.group(3)}{key}: {problem}"
        if field in HEADER_FIELDS:
            return DecodeError(f"bad header: {where}", "bad_header")
        return DecodeError(where, "out_of_range" if _BOUND.match(text) else "wrong_type")

    def _class_of(self, data: bytes) -> type[Message] | None:
        """The class a datagram's tag names, if it is ours (on the error path only)."""
        try:
            items = _RAW_ITEMS.decode(memoryview(data)[PREFIX:])
            tag = msgspec.msgpack.decode(items[0], type=int)
        except (msgspec.MsgspecError, IndexError, RecursionError):
            return None
        return self._by_tag.get(tag)


def _structs(classes: tuple[type[Message], ...]) -> list[mi.StructType]:
    """Every struct type a datagram of these classes can hold (the classes' own too)."""
    found: dict[type, mi.StructType] = {}
    pending: list[Any] = list(mi.multi_type_info(classes)) if classes else []
    while pending:
        node = pending.pop()
        if isinstance(node, mi.StructType):
            if node.cls in found:
                continue
            found[node.cls] = node
            pending.extend(field.type for field in node.fields)
        elif isinstance(node, mi.Type):
            for name in node.__struct_fields__:
                value = getattr(node, name)
                pending.extend(value if isinstance(value, tuple) else (value,))
    return list(found.values())


def _struct_cost(node: mi.StructType) -> int:
    """Most bytes a struct of this type costs per datagram byte that makes it.

    The fewest bytes that make one: a one-byte array or map header, its tag if it
    has one, and one byte per required field (the values read off the wire are
    counted per byte anyway). What they cost: the struct's own object (with the
    collector's header), its slot in a container, and one new object per
    ``default_factory`` field (shared defaults cost nothing).
    """
    cost = node.cls.__basicsize__ + _GC_HEADER + _POINTER
    fewest = 1 + (node.tag is not None)
    for field in node.fields:
        if field.required:
            fewest += 1
        elif field.default_factory is not msgspec.NODEFAULT:
            cost += sys.getsizeof(field.default_factory())
    return -(-cost // fewest)


def _no_message(data: Any) -> Message:
    """The decoder of a stack without messages: whatever arrives is of no type it knows."""
    raise DecodeError("this robot's stack has no messages", "unknown_type")


def _by_tag(classes: tuple[type[Message], ...]) -> dict[int, type[Message]]:
    """The stack's classes by tag; two classes with one tag cannot share a stack."""
    found: dict[int, type[Message]] = {}
    for cls in classes:
        if not (isinstance(cls, type) and issubclass(cls, Message)) or cls is Message:
            raise MessageDefinitionError(f"{cls!r} is not a message class (a Message subclass)")
        tag: int = cls.__struct_config__.tag  # type: ignore[assignment]  # ours are ints
        other = found.setdefault(tag, cls)
        if other is not cls:
            raise MessageDefinitionError(
                f"{_where(other)} and {_where(cls)} have one tag ({tag}, wire name "
                f"{wire_name(cls)!r}) and cannot be messages of one stack: pass "
                "messages=[...] without one of them, or give one @message(name=...)"
            )
    return found


def _where(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def _named(msg: Message) -> str:
    return type(msg).__name__


def _which_field(msg: Message) -> str:
    """Names the first field msgspec refuses, to make encode errors actionable."""
    encode = msgspec.msgpack.Encoder(enc_hook=_encode_custom).encode
    for name in type(msg).__struct_fields__:
        try:
            encode(getattr(msg, name))
        except (TypeError, ValueError, OverflowError, RecursionError, msgspec.EncodeError):
            return f"field {name!r}: "
    return ""


def _brief_error(exc: BaseException) -> str:
    """``Type: message``, cut short: an error about hostile bytes may quote them."""
    text = f"{type(exc).__name__}: {exc}"
    return text if len(text) <= 200 else f"{text[:200]}..."


def _encode_custom(obj: Any) -> Any:
    """Packs what msgspec cannot: numpy arrays (``[dtype, shape, bytes]``) and scalars."""
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in _NUMERIC_KINDS:
            raise TypeError(f"cannot send an array of dtype {obj.dtype} (only numeric dtypes)")
        return (obj.dtype.str, obj.shape, obj.tobytes())
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"cannot encode a value of type {type(obj).__qualname__}")


def _decode_custom(kind: type, value: Any) -> Any:
    """Builds a numpy array from ``[dtype, shape, bytes]``, checked before anything is allocated.

    Nothing is allocated for the array until the bytes present are exactly what
    the dtype and shape need: a datagram claiming 10**9 elements costs nothing.
    """
    if (get_origin(kind) or kind) is not np.ndarray:  # pragma: no cover - refused earlier
        raise TypeError(f"no decoder for {kind!r}")
    if not (isinstance(value, list) and len(value) == 3):
        raise TypeError("expected an ndarray as [dtype, shape, data]")
    dtype_text, shape, data = value
    if type(dtype_text) is not str or _DTYPE_TEXT.fullmatch(dtype_text) is None:
        raise TypeError("expected a numeric dtype code like '<f8'")
    if not isinstance(shape, list) or len(shape) > _MAX_NDIM:
        raise TypeError("expected a shape of at most 32 dimensions")
    if not all(type(n) is int and n >= 0 for n in shape) or type(data) is not bytes:
        raise TypeError("expected a shape of non-negative ints and bytes of data")
    dtype = np.dtype(dtype_text)
    count = 1
    for n in shape:
        count *= n
    if count * dtype.itemsize != len(data):
        raise TypeError(f"shape {shape} of {dtype_text} does not match {len(data)} bytes")
    try:
        # copy(): frombuffer over bytes is read-only; users expect a normal array.
        return np.frombuffer(data, dtype=dtype).reshape(shape).copy()
    except ValueError:  # e.g. shape (0, 2**62, 2**62): no data, but too big for numpy
        raise TypeError(f"bad shape {shape}") from None
