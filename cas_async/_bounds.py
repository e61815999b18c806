"""Bounds on numeric message fields, checked when a message arrives.

A field's annotation may carry bounds with :data:`typing.Annotated`::

    @message
    class Meet(Message):
        x: Annotated[float, Finite]                 # no NaN, no infinity
        speed: Annotated[float, Finite, Bounds(ge=0)]
        seats: Annotated[int, Bounds(ge=1, le=8)]
        path: list[Annotated[float, Finite]]        # every element

The decoder checks them, so a layer never sees a value outside them: a message
that breaks one is dropped and counted as ``decode.out_of_range``, like any other
malformed datagram. The sender does not check (types are not checked on send
either). Bounds are part of the message's schema, hence of the stack
fingerprint: robots must agree on them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

__all__ = ["Bounds", "Finite"]


@dataclass(frozen=True, slots=True)
class Bounds:
    """Bounds on an ``int`` or ``float`` field (see the module docs).

    Attributes:
        ge: the value must be ``>= ge``.
        gt: the value must be ``> gt``.
        le: the value must be ``<= le``.
        lt: the value must be ``< lt``.
        finite: a float must be finite (no NaN, no infinity).

    Any bound refuses NaN. Several ``Bounds`` on one field all apply.

    Raises:
        ValueError: a bound is NaN, or the bounds leave no value.
    """

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    finite: bool = False

    def __post_init__(self) -> None:
        for name in ("ge", "gt", "le", "lt"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or math.isnan(value)):
                raise ValueError(f"Bounds.{name} must be a number, got {value!r}")
        low = max((b for b in (self.ge, self.gt) if b is not None), default=-math.inf)
        high = min((b for b in (self.le, self.lt) if b is not None), default=math.inf)
        if low > high or (low == high and (self.gt is not None or self.lt is not None)):
            raise ValueError(f"{self!r} leaves no value")

    def __and__(self, other: Bounds) -> Bounds:
        """Both bounds at once."""

        def low(a: float | None, b: float | None) -> float | None:
            return b if a is None else a if b is None else max(a, b)

        def high(a: float | None, b: float | None) -> float | None:
            return b if a is None else a if b is None else min(a, b)

        return Bounds(
            low(self.ge, other.ge),
            low(self.gt, other.gt),
            high(self.le, other.le),
            high(self.lt, other.lt),
            self.finite or other.finite,
        )

    def admits(self, value: float) -> bool:
        """Whether ``value`` is within these bounds (NaN never is, under any bound)."""
        if self.finite and not math.isfinite(value):
            return False
        return (
            (self.ge is None or value >= self.ge)
            and (self.gt is None or value > self.gt)
            and (self.le is None or value <= self.le)
            and (self.lt is None or value < self.lt)
        )

    @property
    def text(self) -> str:
        """The bounds in the schema (and fingerprint), e.g. ``"finite,>=0"``."""
        parts = ["finite"] if self.finite else []
        for symbol, value in ((">=", self.ge), (">", self.gt), ("<=", self.le), ("<", self.lt)):
            if value is not None:
                parts.append(f"{symbol}{value!r}")
        return ",".join(parts)


Finite: Final = Bounds(finite=True)
"""A float field must be finite: no NaN, no infinity."""
