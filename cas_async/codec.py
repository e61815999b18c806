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

from collections.abc import Mapping
from typing import Any, Final

import msgpack
import numpy as np
from msgpack import unpackb as _unpackb

from .codegen import compiled, undispatchable
from .errors import DecodeError, EncodeError
from .message import Message, MessageSpec, nested_to_wire, spec_of
from .schema import ndarray_to_wire

__all__ = ["DEFAULT_MAX_DATAGRAM", "MIN_DATAGRAM", "Codec"]

DEFAULT_MAX_DATAGRAM: Final = 64 * 1024
"""Largest datagram encoded or accepted, in bytes, unless configured otherwise."""

MIN_DATAGRAM: Final = 64
"""Smallest datagram limit accepted: below it not even a header with a small field fits."""


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
        if max_size < MIN_DATAGRAM:
            raise ValueError(f"max_size must be at least {MIN_DATAGRAM} bytes, got {max_size}")
        self.fingerprint = fingerprint
        self.max_size = max_size
        generated = [compiled(spec) for spec in specs.values()]
        self._by_id = {c.spec.type_id: c.decode for c in generated}
        self._by_class = {c.spec.cls: c for c in generated}
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
        try:
            t = _unpackb(data, use_list=False, strict_map_key=False)
        except Exception as exc:  # the unpacker raises many types; all mean "malformed"
            raise DecodeError(f"not a msgpack datagram: {type(exc).__name__}: {exc}") from None
        try:
            decode = self._by_id[t[1]]
        except Exception:  # not an array, too short, unhashable or unknown type id
            raise undispatchable(t, self.fingerprint) from None
        try:
            return decode(t, self.fingerprint)  # checks the header, fingerprint included
        except RecursionError:  # bare list/dict fields or recursive messages, nested deeply
            raise DecodeError("values nest too deeply", "wrong_type") from None


def _which_field(msg: Message, spec: MessageSpec) -> str:
    """Names the first field msgpack refuses, to make encode errors actionable."""
    pack = msgpack.Packer(default=_encode_default, use_bin_type=True).pack
    for attr in spec.field_names:
        try:
            pack(getattr(msg, attr))
        except (TypeError, ValueError, OverflowError):
            return f"field {attr!r}: "
    return ""
