"""Datagrams made by hand, as a robot of a given stack encodes them (or nearly: forged).

A datagram is the stack's fingerprint (4 bytes, big-endian), then one msgpack
array: the message's tag, its fields, then the header (``msg_type, msg_id,
robot_id, src_layer, dst_layer, corr_id``). See ``cas_async._wire._codec``.
"""

from __future__ import annotations

from collections.abc import Sequence

import msgpack

from cas_async import Message

__all__ = ["datagram", "tag_of"]


def tag_of(cls: type[Message]) -> int:
    """The tag a message class carries on the wire."""
    tag = cls.__struct_config__.tag
    assert isinstance(tag, int)
    return tag


def datagram(
    fingerprint: int,
    tag: int | type[Message],
    fields: Sequence[object],
    *,
    msg_type: object = 1,
    msg_id: object = 1,
    robot_id: object = 2,
    src: object = 0,
    dst: object = 0,
    corr_id: object = 0,
    header: Sequence[object] | None = None,
) -> bytes:
    """The bytes of a datagram: ``fields`` packed as given, nothing checked."""
    if not isinstance(tag, int):
        tag = tag_of(tag)
    if header is None:
        header = (msg_type, msg_id, robot_id, src, dst, corr_id)
    body: bytes = msgpack.packb([tag, *fields, *header])
    return fingerprint.to_bytes(4, "big") + body
