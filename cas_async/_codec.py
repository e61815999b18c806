"""The msgpack wire format of external messages, with limits and strict decoding.

A datagram is one msgpack array::

    [fingerprint, type_id, msg_id, msg_type, robot_id, src_layer, dst_layer, corr_id, *fields]

Most messages take a fast path built on msgspec (see :mod:`cas_async._codegen`):
encoding packs the header and fields, once a generated check has vouched for
their types, and decoding reads the fingerprint and type id, then parses the
whole datagram against the class's exact wire types in C. Anything that path
declines takes the precise one: a reused ``msgpack.Packer``, or a bounded read of
the datagram item by item (:mod:`cas_async._datagram`: arrays as tuples) followed
by a decoder generated once per message class, which checks simple fields with
inlined ``type(v) is int`` tests and calls the converters of :mod:`cas_async._schema`
when a field needs it. Both paths give the same message or the same error; only
their cost differs. Every problem with untrusted bytes raises
:class:`~cas_async._errors.DecodeError`; nothing is ever unpickled.

Decoding is bounded whatever a datagram claims. Memory: see
:attr:`Codec.max_decode_bytes`. Time: the precise path first checks the whole
structure without building anything (a few nanoseconds a byte), then builds only
what the header and the class's declared field types call for, so a hostile
datagram costs about what a well-formed one of its size does.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Final

import msgpack
import msgspec
import numpy as np

from ._codegen import HEADER_LEN, compiled, undispatchable, wrong_arity
from ._datagram import FieldPlan, read_datagram
from ._errors import DecodeError, EncodeError
from ._fingerprint import stack_fingerprint
from ._message import (
    Message,
    MessageSpec,
    nested_to_wire,
    registry_generation,
    spec_of,
    specs_for,
)
from ._schema import ndarray_to_wire

__all__ = ["DEFAULT_MAX_DATAGRAM", "MIN_DATAGRAM", "Codec"]

DEFAULT_MAX_DATAGRAM: Final = 64 * 1024
"""Largest datagram encoded or accepted, in bytes, unless configured otherwise."""

MIN_DATAGRAM: Final = 64
"""Smallest datagram limit accepted: below it not even a header with a small field fits."""

_BYTES_PER_BYTE: Final = 256
"""Most bytes of Python objects one datagram byte decodes into, with margin.

Worst cases measured with tracemalloc (tests/test_decode_limits.py): arrays nested
in arrays, one byte each, in a bare ``list`` field, about 140 bytes per byte (a
tuple from msgpack, then the list it becomes); chains of one-entry maps, two bytes
each, about 115; empty maps (one byte each) about 80.
"""

_RESERVED_PER_ITEM: Final = 8
"""What msgpack reserves per array item it reads (one pointer), before building it."""

_DECODE_OVERHEAD: Final = 256 * 1024
_SHARED_CODECS: Final = 32  # stacks whose codec a thread keeps (Codec.shared)
_per_thread: Final = threading.local()
"""Fixed allowance of a decode: unpacker state, frames, one error message."""


def _encode_default(obj: Any) -> Any:
    """Packs what msgpack cannot: nested messages, numpy arrays and scalars."""
    if isinstance(obj, Message):
        return nested_to_wire(obj)
    if isinstance(obj, np.ndarray):
        return ndarray_to_wire(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, int):  # msgpack calls us for ints it cannot carry
        raise OverflowError(f"{obj} is outside the 64-bit integer range msgpack carries")
    raise TypeError(f"cannot encode a value of type {type(obj).__qualname__}")


class Codec:
    """Encodes and decodes the external messages of one robot.

    Decoding a datagram never allocates more than :attr:`max_decode_bytes` bytes,
    whatever it claims (arrays or maps of 2**32 items, strings of 4 GiB, arrays
    nested 1024 deep, numpy arrays of 10**9 elements)::

        max_decode_bytes = (8 + 1 + 256) * max_size + 256 KiB

    Every length a datagram claims is checked against the bytes present before
    anything is built, so msgpack reserves at most 8 bytes per item there is (the
    first term), its buffer holds one copy of the datagram (the second), and the
    Python objects built take at most 256 bytes per byte; the last is a fixed
    allowance. With the default 64 KiB datagrams that is about 17 MiB, all of it
    freed when ``decode`` returns.

    Args:
        specs: the message types this robot accepts, by type id.
        fingerprint: this robot's stack fingerprint (see :func:`stack_fingerprint`).
        max_size: largest datagram, in bytes, encoded or accepted.
    """

    passes_objects = False
    """Receivers get bytes, never the objects sent."""

    __slots__ = (
        "_arity",
        "_by_class",
        "_by_id",
        "_fast",
        "_fast_encoders",
        "_fast_pack",
        "_pack",
        "_plans",
        "_prefix_length",
        "_prefix_lengths",
        "fingerprint",
        "max_size",
    )

    def __init__(
        self,
        specs: Mapping[int, MessageSpec],
        fingerprint: int,
        max_size: int = DEFAULT_MAX_DATAGRAM,
    ) -> None:
        if max_size < MIN_DATAGRAM:
            raise ValueError(f"max_size must be at least {MIN_DATAGRAM} bytes, got {max_size}")
        self.fingerprint = fingerprint
        self.max_size = max_size
        generated = [compiled(spec) for spec in specs.values()]
        self._by_id = {c.spec.type_id: c.decode for c in generated}
        self._arity = {c.spec.type_id: (c.spec.name, len(c.spec.field_names)) for c in generated}
        # Per type id, how the precise path reads each field (see _datagram).
        self._plans = {c.spec.type_id: _plans(c.spec) for c in generated}
        self._by_class = {c.spec.cls: c for c in generated}
        # A datagram of a fast class starts with bytes known in advance: the array
        # header (its arity is fixed), our fingerprint, its type id. Those bytes pick
        # the class; a datagram whose start is anything else takes the precise path.
        self._fast: dict[bytes, tuple[Callable[[bytes], Any], Callable[[Any], Message]]] = {
            _prefix(c.spec, fingerprint): (c.fast_decode, c.build)
            for c in generated
            if c.fast_decode is not None and c.build is not None
        }
        lengths = sorted({len(prefix) for prefix in self._fast}, reverse=True)
        self._prefix_length = lengths.pop() if lengths else 0
        self._prefix_lengths = tuple(lengths)  # others, for type ids of other sizes
        self._fast_encoders = {
            c.spec.cls: c.fast_encode for c in generated if c.fast_encode is not None
        }
        self._pack = msgpack.Packer(default=_encode_default, use_bin_type=True).pack
        self._fast_pack = msgspec.msgpack.Encoder().encode

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
        specs = specs_for(messages)
        return cls(specs, stack_fingerprint(layers, specs), max_size)

    @classmethod
    def shared(
        cls,
        layers: int,
        messages: tuple[type[Message], ...] | None,
        max_size: int = DEFAULT_MAX_DATAGRAM,
    ) -> Codec:
        """:meth:`for_stack`, made once per thread for robots of one stack to share.

        A codec holds nothing of a robot's, and making one costs about 0.5 ms (a
        decoder per field): ten thousand robots of one stack share one. Shared
        within a thread only, as the packer it holds is not thread-safe.
        """
        key = (layers, messages, registry_generation() if messages is None else 0, max_size)
        codecs: dict[Any, Codec] | None = getattr(_per_thread, "codecs", None)
        if codecs is None:
            codecs = _per_thread.codecs = {}
        codec = codecs.get(key)
        if codec is None:
            codec = cls.for_stack(layers, messages, max_size)
            if len(codecs) >= _SHARED_CODECS:  # bounded: tests make stacks by the hundred
                del codecs[next(iter(codecs))]
            codecs[key] = codec
        return codec

    @property
    def message_classes(self) -> frozenset[type[Message]]:
        """The message classes this codec carries."""
        return frozenset(self._by_class)

    @property
    def max_decode_bytes(self) -> int:
        """Most bytes decoding one datagram allocates at once (see the class docs)."""
        per_byte = _RESERVED_PER_ITEM + 1 + _BYTES_PER_BYTE  # reservations, buffer, objects
        return per_byte * self.max_size + _DECODE_OVERHEAD

    def encode(self, msg: Message) -> bytes:
        """The datagram for ``msg``.

        Raises:
            EncodeError: a field holds a value msgpack cannot carry, the message type
                is not accepted by this robot, or the datagram exceeds ``max_size``.
        """
        fast = self._fast_encoders.get(type(msg))
        if fast is not None:
            data = fast(msg, self.fingerprint, self._fast_pack)
            if data is not None and len(data) <= self.max_size:
                return data
        return self._encode_precisely(msg)

    def _encode_precisely(self, msg: Message) -> bytes:
        """Encodes with msgpack: the datagram, or the precise error."""
        entry = self._by_class.get(type(msg))
        if entry is None:
            spec = spec_of(type(msg))  # raises when @message was forgotten
            raise EncodeError(f"{spec.name} is not among the messages this robot's stack accepts")
        try:
            data = entry.encode(msg, self.fingerprint, self._pack)
        except (TypeError, ValueError, OverflowError) as exc:
            raise EncodeError(
                f"cannot encode {entry.spec.name}: {_which_field(msg, entry.spec)}{exc}"
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
        if type(data) is not bytes:
            data = bytes(data)  # a bytearray or memoryview: its slices are not hashable
        fast = self._fast.get(data[: self._prefix_length])
        if fast is None and self._prefix_lengths:
            fast = next(
                filter(None, (self._fast.get(data[:n]) for n in self._prefix_lengths)), None
            )
        if fast is not None:
            try:
                row = fast[0](data)
            except Exception:  # refused, or nested too deep: the precise path explains
                return self._decode_precisely(data)
            return fast[1](row)
        return self._decode_precisely(data)

    def _decode_precisely(self, data: bytes) -> Message:
        """Decodes with the generated checks: the precise error, or the message.

        Read item by item (see :mod:`cas_async._datagram`), so that a hostile
        datagram costs about what a well-formed one of its size does.
        """
        header, fields, count = read_datagram(data, self._plans.get)
        fingerprint = self.fingerprint
        if fields is None:  # a header only: too short, another stack, unknown type, arity
            arity = self._arity.get(header[1]) if len(header) == HEADER_LEN else None
            if arity is None:
                raise undispatchable(header, fingerprint)
            raise wrong_arity(*arity, header, count, fingerprint)
        try:
            return self._by_id[header[1]]((*header, *fields), fingerprint)
        except DecodeError:
            raise
        except RecursionError:  # bare list/dict fields or recursive messages, nested deeply
            raise DecodeError("values nest too deeply", "wrong_type") from None
        except Exception as exc:  # a converter's oversight must not reach the robot
            raise DecodeError(f"cannot decode: {_brief_error(exc)}") from None


def _plans(spec: MessageSpec) -> tuple[FieldPlan, ...]:
    """How the precise path reads each field of ``spec`` (see :mod:`cas_async._datagram`)."""
    return tuple(
        FieldPlan(
            f"{spec.name}.{name}",
            kind.scalar,
            None if kind.wire is None else msgspec.msgpack.Decoder(kind.wire).decode,
        )
        for name, kind in zip(spec.field_names, spec.field_types, strict=True)
    )


def _prefix(spec: MessageSpec, fingerprint: int) -> bytes:
    """How every datagram of ``spec`` begins: array header, fingerprint, type id."""
    items = HEADER_LEN + len(spec.field_names)
    header = bytes([0x90 | items]) if items < 16 else b"\xdc" + items.to_bytes(2, "big")
    encoded: bytes = msgpack.packb(fingerprint) + msgpack.packb(spec.type_id)
    return header + encoded


def _brief_error(exc: BaseException) -> str:
    """``Type: message``, cut short: an error about hostile bytes may quote them."""
    text = f"{type(exc).__name__}: {exc}"
    return text if len(text) <= 200 else f"{text[:200]}..."


def _which_field(msg: Message, spec: MessageSpec) -> str:
    """Names the first field msgpack refuses, to make encode errors actionable."""
    pack = msgpack.Packer(default=_encode_default, use_bin_type=True).pack
    for attr in spec.field_names:
        try:
            pack(getattr(msg, attr))
        except (TypeError, ValueError, OverflowError):
            return f"field {attr!r}: "
    return ""
