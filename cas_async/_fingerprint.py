"""Stack fingerprints: robots may only talk when theirs are equal (DESIGN rule 5)."""

from __future__ import annotations

import zlib
from collections.abc import Mapping

from ._message import MessageSpec

__all__ = ["describe_fingerprint", "stack_fingerprint"]


def stack_fingerprint(layer_count: int, specs: Mapping[int, MessageSpec]) -> int:
    """A 32-bit summary of a robot's stack: layer count (top byte) and message set.

    The layer count is kept readable so a mismatch can be explained ("4 layers,
    ours has 5"); the message set is a CRC of every message's wire schema.
    """
    text = "\n".join(spec.schema for _, spec in sorted(specs.items()))
    return ((layer_count & 0xFF) << 24) | (zlib.crc32(text.encode()) & 0xFFFFFF)


def describe_fingerprint(fingerprint: int) -> str:
    """Human-readable form: ``"5 layers, message set 0x1a2b3c"``."""
    return f"{fingerprint >> 24} layers, message set {fingerprint & 0xFFFFFF:#08x}"
