"""The attachment rmw_zenoh requires on every sample: sequence number, timestamp, GID.

33 bytes, binary since rmw_zenoh#600 (Jazzy 0.2.4; rmw_zenoh ``docs/design.md``,
"Publishers"): the sequence number (int64, little-endian, per publisher from 1),
the source timestamp (int64 ns since the Unix epoch, little-endian), one byte with
the GID's length (16) and the 16-byte GID of the publisher. A subscriber of
rmw_zenoh drops a sample that has none.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Final

__all__ = ["ATTACHMENT_SIZE", "Attachment", "GID_SIZE"]

GID_SIZE: Final = 16
_HEAD: Final = struct.Struct("<qqB")
ATTACHMENT_SIZE: Final = _HEAD.size + GID_SIZE


@dataclass(frozen=True, slots=True)
class Attachment:
    """What a sample says about where it comes from."""

    sequence: int
    timestamp_ns: int
    gid: bytes

    def to_bytes(self) -> bytes:
        """The 33 bytes rmw_zenoh reads."""
        return _HEAD.pack(self.sequence, self.timestamp_ns, GID_SIZE) + self.gid

    @classmethod
    def from_bytes(cls, data: bytes) -> Attachment:
        """Reads an attachment.

        Raises:
            ValueError: not 33 bytes, or a GID length other than 16.
        """
        if len(data) != ATTACHMENT_SIZE:
            raise ValueError(f"attachment of {len(data)} bytes, expected {ATTACHMENT_SIZE}")
        sequence, timestamp, length = _HEAD.unpack_from(data)
        if length != GID_SIZE:
            raise ValueError(f"attachment GID of {length} bytes, expected {GID_SIZE}")
        return cls(sequence, timestamp, bytes(data[_HEAD.size :]))
