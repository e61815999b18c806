"""A message through a stack's codec and back, compared field by field."""

from __future__ import annotations

import typing
from collections.abc import Iterable, Sequence
from typing import Final, TypeVar

import msgspec
import numpy as np

from .. import Message, message_fields
from ..transport import Codec

__all__ = ["assert_roundtrip"]

M = TypeVar("M", bound=Message)


def assert_roundtrip(
    msg: M, *, layers: int = 1, messages: Iterable[type[Message]] | None = None
) -> M:
    """Encodes ``msg`` as a robot of that stack would and decodes it; returns the copy.

    Header fields are kept as they are (set ``msg_id``, ``robot_id`` and the levels
    first to test them too); a ``msg_id`` of 0 (not sent) travels as 1, since no
    datagram carries id 0, and comes back as 0.

    Args:
        msg: the message.
        layers: the stack's height.
        messages: the stack's messages (default: ``msg``'s class alone).

    Raises:
        AssertionError: the copy differs from ``msg`` (the fields that differ are
            named), or the message cannot be encoded or decoded (with the codec's
            reason).
    """
    codec = Codec.for_stack(layers, [type(msg)] if messages is None else messages)
    sent = msg
    if not msg.msg_id:  # not sent yet: no datagram carries id 0, so it travels as 1
        sent = msgspec.structs.replace(msg, msg_id=1)
    try:
        copy = codec.decode(codec.encode(sent))
    except Exception as exc:
        raise AssertionError(f"{msg!r} does not survive the codec: {exc}") from exc
    if sent is not msg:
        copy.msg_id = 0
    if type(copy) is not type(msg):
        raise AssertionError(f"{msg!r} came back as another class: {copy!r}")
    differ = [
        f"{name}: {getattr(msg, name)!r} became {getattr(copy, name)!r}"
        for name in (*message_fields(type(msg)), *_HEADER)
        if not _same(getattr(msg, name), getattr(copy, name))
    ]
    if differ:
        raise AssertionError(f"{msg!r} came back as {copy!r}: " + "; ".join(differ))
    return copy


def _same(a: object, b: object) -> bool:
    """Equal, NaN counting as equal to NaN wherever it is (a float, in a list, an array)."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (a != a and b != b)
    if isinstance(a, list | tuple) and type(a) is type(b):
        other = typing.cast(Sequence[object], b)
        return len(a) == len(other) and all(_same(x, y) for x, y in zip(a, other, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, msgspec.Struct) and type(a) is type(b):
        names = message_fields(type(a)) if isinstance(a, Message) else type(a).__struct_fields__
        return all(_same(getattr(a, name), getattr(b, name)) for name in names)
    if isinstance(a, np.ndarray) and isinstance(b, np.ndarray):
        floating = a.dtype.kind in "fc"
        return a.dtype == b.dtype and bool(np.array_equal(a, b, equal_nan=floating))
    return bool(a == b)


_HEADER: Final = ("msg_id", "msg_type", "robot_id", "src_layer", "dst_layer", "corr_id")
