"""Per-layer message counters: plain integer slots, cheap to bump on hot paths."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = ["LayerCounters", "count_sent_external", "count_sent_internal"]

_TOTALS = (
    "sent_internal",
    "sent_external",
    "received_internal",
    "received_external",
    "forwarded",
    "restarts",
)


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
    restarts: int = 0
    """Times this layer was restarted after raising (see ``Robot(restart=...)``)."""
    internal_by_type: dict[type[Any], int] = field(default_factory=dict)
    """``sent_internal`` split by message class."""
    external_by_type: dict[type[Any], int] = field(default_factory=dict)
    """``sent_external`` split by message class."""

    def as_dict(self) -> dict[str, int]:
        """The totals by name (the per-class splits are not included)."""
        return {name: getattr(self, name) for name in _TOTALS}

    def add(self, other: LayerCounters) -> None:
        """Adds ``other``'s totals to these (the per-class splits are not added)."""
        for name in _TOTALS:
            setattr(self, name, getattr(self, name) + getattr(other, name))

    def add_by_name(self, internal: dict[str, int], external: dict[str, int]) -> None:
        """Adds the per-class splits to ``internal`` and ``external``, by class name."""
        for split, into in ((self.internal_by_type, internal), (self.external_by_type, external)):
            for cls, n in split.items():
                into[cls.__name__] = into.get(cls.__name__, 0) + n

    def add_by_type(self, internal: dict[type[Any], int], external: dict[type[Any], int]) -> None:
        """Adds the per-class splits to ``internal`` and ``external``, by class."""
        for split, into in ((self.internal_by_type, internal), (self.external_by_type, external)):
            for cls, n in split.items():
                into[cls] = into.get(cls, 0) + n


# The runtime's own (not on LayerCounters, whose public face is what users read).
def count_sent_internal(counters: LayerCounters, kind: type[Any]) -> None:
    """One internal message of class ``kind`` sent by the layer of ``counters``."""
    counters.sent_internal += 1
    by_type = counters.internal_by_type
    by_type[kind] = by_type.get(kind, 0) + 1


def count_sent_external(counters: LayerCounters, kind: type[Any]) -> None:
    """One external message of class ``kind`` sent by the layer of ``counters``."""
    counters.sent_external += 1
    by_type = counters.external_by_type
    by_type[kind] = by_type.get(kind, 0) + 1
