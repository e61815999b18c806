"""The msgpack wire format of external messages, with limits and strict decoding.

A datagram is one msgpack array::

    [fingerprint, type_id, msg_id, msg_type, robot_id, src_layer, dst_layer, corr_id, *fields]

Most messages take a fast path built on msgspec (see :mod:`cas_async._codegen`):
encoding packs the header and fields, once a generated check has vouched for
their types, and decoding reads the fingerprint and type id, then parses the
whole datagram against the class's exact wire types in C. Anything that path
declines takes the precise one: a reused ``msgpack.Packer``, or an unpack (arrays
as tuples) followed by a decoder generated once per message class, which checks
simple fields with inlined ``type(v) is int`` tests and calls the converters of
:mod:`cas_async._schema` when a field needs it. Both paths give the same message
or the same error; only their cost differs. Every problem with untrusted bytes
raises :class:`~cas_async._errors.DecodeError`; nothing is ever unpickled.

Decoding allocates a bounded amount of memory whatever a datagram claims (see
:attr:`Codec.max_decode_bytes`). msgpack's C unpacker reserves the slots of an
array when it reads the array's header, before any item arrives, and keeps up to
1024 arrays open at once; so it reads arrays of at most 256 items, and the rare
datagram with a longer array is read again by msgpack's pure-Python unpacker,
which only allocates for items it has actually read.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any, Final

import msgpack
import msgspec
import numpy as np
from msgpack import fallback
from msgpack import unpackb as _unpackb

from ._codegen import HEADER_LEN, compiled, undispatchable
from ._errors import DecodeError, EncodeError
from ._fingerprint import stack_fingerprint
from ._message import Message, MessageSpec, nested_to_wire, spec_of, specs_for
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

_FAST_ITEMS: Final = 256
"""Longest array msgpack's C unpacker reads; longer ones take the pure-Python unpacker."""

_OPEN_ARRAYS: Final = 1024
"""Arrays msgpack's C unpacker keeps open at once (nesting deeper is malformed)."""

_RESERVED_PER_ARRAY: Final = 64
"""An array's own allocation besides its slots: tuple header and garbage-collector link."""

_DECODE_OVERHEAD: Final = 256 * 1024
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

        max_decode_bytes = 1024 * (8 * 256 + 64) + 256 * max_size + 256 KiB

    The first term (about 2 MiB) is msgpack reserving 8 bytes per declared item
    for each of up to 1024 open arrays of up to 256 items (longer arrays are read
    by a slower unpacker that reserves nothing); the second, the Python objects
    built from the datagram's bytes, at most 256 bytes per byte; the third, a
    fixed allowance. With the default 64 KiB datagrams that is about 19 MiB, all
    of it freed when ``decode`` returns.

    Args:
        specs: the message types this robot accepts, by type id.
        fingerprint: this robot's stack fingerprint (see :func:`stack_fingerprint`).
        max_size: largest datagram, in bytes, encoded or accepted.
    """

    passes_objects = False
    """Receivers get bytes, never the objects sent."""

    __slots__ = (
        "_by_class",
        "_by_id",
        "_fast",
        "_fast_encoders",
        "_fast_pack",
        "_pack",
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

    @property
    def message_classes(self) -> frozenset[type[Message]]:
        """The message classes this codec carries."""
        return frozenset(self._by_class)

    @property
    def max_decode_bytes(self) -> int:
        """Most bytes decoding one datagram allocates at once (see the class docs)."""
        reserved = _OPEN_ARRAYS * (8 * _FAST_ITEMS + _RESERVED_PER_ARRAY)
        return reserved + _BYTES_PER_BYTE * self.max_size + _DECODE_OVERHEAD

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
        """Decodes with msgpack and the generated checks: the precise error, or the message."""
        try:
            # Only the array limit is given: strings, bytes, ext types and maps are
            # limited to len(data) by default (and msgpack allocates them only once
            # their bytes are there); every keyword costs time on this hot path.
            t = _unpackb(data, use_list=False, strict_map_key=False, max_array_len=_FAST_ITEMS)
        except Exception as exc:  # the unpacker raises many types; all mean "malformed"
            t = self._unpack_long_arrays(data, exc)
        fingerprint = self.fingerprint
        try:
            try:
                decode = self._by_id[t[1]]
            except Exception:  # not an array, too short, unhashable or unknown type id
                raise undispatchable(t, fingerprint) from None
            return decode(t, fingerprint)  # checks the header, fingerprint included
        except DecodeError:
            raise
        except RecursionError:  # bare list/dict fields or recursive messages, nested deeply
            raise DecodeError("values nest too deeply", "wrong_type") from None
        except Exception as exc:  # a converter's oversight must not reach the robot
            raise DecodeError(f"cannot decode: {_brief_error(exc)}") from None

    def _unpack_long_arrays(self, data: bytes, exc: Exception) -> Any:
        """Unpacks a datagram the C unpacker refused for a long array, else explains.

        The pure-Python unpacker builds arrays as items arrive, so a datagram
        claiming long arrays it does not hold costs only what it holds; it is about
        20 times slower, which only datagrams with arrays over 256 items pay.
        """
        if type(exc) is not ValueError or "max_array_len" not in str(exc):
            raise DecodeError(f"not a msgpack datagram: {_brief_error(exc)}") from None
        size = self.max_size  # no item, string or entry can be longer than the datagram
        try:
            return fallback.unpackb(
                data,
                use_list=False,
                strict_map_key=False,
                max_array_len=size,
                max_map_len=size,
                max_str_len=size,
                max_bin_len=size,
                max_ext_len=size,
            )
        except Exception as again:
            raise DecodeError(f"not a msgpack datagram: {_brief_error(again)}") from None


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
