"""Quality of service as rmw_zenoh writes it in liveliness tokens.

A token's last chunk is the entity's QoS in a compact form (``qos_to_keyexpr`` in
rmw_zenoh's ``liveliness_utils.cpp``)::

    <reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:
        <liveliness>,<lease s>,<ns>                   (one line)

Each field equal to rmw_zenoh's default is left empty, so the default QoS of a
``rclcpp`` publisher (reliable, volatile, keep last 10) reads ``::,10:,:,:,,``.
rmw_zenoh's defaults: reliable, volatile, keep last 42, infinite deadline,
lifespan and lease, automatic liveliness. Enum values are those of ``rmw/types.h``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Final

__all__ = ["Durability", "History", "Liveliness", "QoS", "Reliability"]


class Reliability(IntEnum):
    """``rmw_qos_reliability_policy_e``."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class Durability(IntEnum):
    """``rmw_qos_durability_policy_e``."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class History(IntEnum):
    """``rmw_qos_history_policy_e``."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2
    UNKNOWN = 3


class Liveliness(IntEnum):
    """``rmw_qos_liveliness_policy_e`` (2, manual by node, is deprecated and not parsed)."""

    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_TOPIC = 3
    UNKNOWN = 4
    BEST_AVAILABLE = 5


INFINITE: Final = (9223372036, 854775807)
"""``RMW_DURATION_INFINITE`` as (seconds, nanoseconds)."""


@dataclass(frozen=True, slots=True)
class QoS:
    """An entity's quality of service; the defaults are rmw_zenoh's, but for ``depth``.

    ``depth`` defaults to 10, ``rclcpp``'s usual ``create_publisher(topic, 10)``.
    Durations are ``(seconds, nanoseconds)``.
    """

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 10
    deadline: tuple[int, int] = INFINITE
    lifespan: tuple[int, int] = INFINITE
    liveliness: Liveliness = Liveliness.AUTOMATIC
    lease: tuple[int, int] = INFINITE

    def to_key(self) -> str:
        """The compact form a liveliness token carries (fields at rmw_zenoh's default left out)."""
        d = _RMW_ZENOH_DEFAULT

        def part(value: int, default: int) -> str:
            return "" if value == default else str(int(value))

        return (
            f"{part(self.reliability, d.reliability)}:{part(self.durability, d.durability)}:"
            f"{part(self.history, d.history)},{part(self.depth, d.depth)}:"
            f"{part(self.deadline[0], d.deadline[0])},{part(self.deadline[1], d.deadline[1])}:"
            f"{part(self.lifespan[0], d.lifespan[0])},{part(self.lifespan[1], d.lifespan[1])}:"
            f"{part(self.liveliness, d.liveliness)},{part(self.lease[0], d.lease[0])},"
            f"{part(self.lease[1], d.lease[1])}"
        )

    @classmethod
    def from_key(cls, key: str) -> QoS:
        """Parses the compact form as rmw_zenoh's ``keyexpr_to_qos`` does.

        Raises:
            ValueError: not six ``:``-separated parts with their ``,`` components, an
                unknown policy value, or a number that is not one.
        """
        parts = key.split(":")
        if len(parts) < 6:
            raise ValueError(f"QoS {key!r}: expected 6 ':'-separated parts, got {len(parts)}")
        history, deadline, lifespan, liveliness = (
            parts[2].split(","),
            parts[3].split(","),
            parts[4].split(","),
            parts[5].split(","),
        )
        if len(history) < 2 or len(deadline) < 2 or len(lifespan) < 2 or len(liveliness) < 3:
            raise ValueError(f"QoS {key!r}: a part lacks its ','-separated components")
        d = _RMW_ZENOH_DEFAULT
        try:
            return cls(
                reliability=Reliability(int(parts[0])) if parts[0] else d.reliability,
                durability=Durability(int(parts[1])) if parts[1] else d.durability,
                history=History(int(history[0])) if history[0] else d.history,
                depth=_count(history[1], d.depth),
                deadline=(_count(deadline[0], d.deadline[0]), _count(deadline[1], d.deadline[1])),
                lifespan=(_count(lifespan[0], d.lifespan[0]), _count(lifespan[1], d.lifespan[1])),
                liveliness=Liveliness(int(liveliness[0])) if liveliness[0] else d.liveliness,
                lease=(_count(liveliness[1], d.lease[0]), _count(liveliness[2], d.lease[1])),
            )
        except ValueError as exc:
            raise ValueError(f"QoS {key!r}: {exc}") from None


def _count(text: str, default: int) -> int:
    """An unsigned decimal number, or ``default`` for an empty field (``strtoul`` as rmw_zenoh)."""
    if not text:
        return default
    if not (text.isascii() and text.isdigit()):
        raise ValueError(f"{text!r} is not an unsigned number")
    return int(text)


_RMW_ZENOH_DEFAULT: Final = QoS(depth=42)
