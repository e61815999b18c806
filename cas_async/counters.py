"""Per-layer message counters: plain integer slots, cheap to bump on hot paths."""

from __future__ import annotations

from dataclasses import dataclass, fields

__all__ = ["LayerCounters"]


@dataclass(slots=True)
class LayerCounters:
    """What one layer sent, received and forwarded."""

    sent_internal: int = 0
    """Internal messages this layer originated (replies included)."""
    sent_external: int = 0
    """External messages this layer sent (a broadcast counts once per recipient)."""
    received_internal: int = 0
    """Internal messages delivered to this layer's hooks (or to a waiting request)."""
    received_external: int = 0
    """External messages delivered to this layer's hooks (or to a waiting request)."""
    forwarded: int = 0
    """Internal messages passed through this layer to a farther one."""

    def as_dict(self) -> dict[str, int]:
        """The counters by name."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
