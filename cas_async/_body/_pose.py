"""Where a robot is: a 2-D pose, and the heading convention of the whole kit.

Headings are in radians, measured counter-clockwise from the +x axis (so +y is
``pi / 2``), and always normalised to the half-open interval ``(-pi, pi]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from .._errors import SimulationError

__all__ = ["Pose", "normalize_angle"]

_TAU: Final = 2.0 * math.pi


def normalize_angle(angle: float) -> float:
    """The angle equal to ``angle`` modulo a full turn, in ``(-pi, pi]``.

    Raises:
        SimulationError: ``angle`` is NaN or infinite.
    """
    if not math.isfinite(angle):
        raise SimulationError(f"angle must be a finite number of radians, got {angle!r}")
    # remainder() is exact and lands in [-pi, pi]; -pi is folded onto pi so that
    # every direction has exactly one representation.
    wrapped = math.remainder(angle, _TAU)
    return math.pi if wrapped == -math.pi else wrapped


def _finite(name: str, value: float) -> float:
    number = float(value)
    if not math.isfinite(number):
        raise SimulationError(f"{name} must be a finite number, got {value!r}")
    return number


@dataclass(frozen=True, slots=True)
class Pose:
    """A position in the plane and a heading.

    Values are coerced to ``float`` (numpy scalars are accepted) and the heading is
    normalised to ``(-pi, pi]``, so two equal poses compare equal.

    Attributes:
        x: abscissa, in distance units.
        y: ordinate, in distance units.
        heading: radians counter-clockwise from the +x axis.

    Raises:
        SimulationError: a coordinate or the heading is NaN or infinite.
    """

    x: float
    y: float
    heading: float = 0.0

    def __post_init__(self) -> None:
        x, y, heading = self.x, self.y, self.heading
        if (
            type(x) is float  # not a subclass (numpy's float64): those are coerced below
            and type(y) is float
            and type(heading) is float
            and x - x == 0.0  # finite: inf - inf and NaN - NaN are NaN
            and y - y == 0.0
            and -math.pi < heading <= math.pi  # then normalize_angle returns it, bit for bit
        ):
            return  # most poses: made from another's floats, nothing to coerce or normalise
        # object.__setattr__ is the documented way to normalise a frozen dataclass.
        object.__setattr__(self, "x", _finite("x", self.x))
        object.__setattr__(self, "y", _finite("y", self.y))
        heading = _finite("heading", self.heading)
        object.__setattr__(self, "heading", normalize_angle(heading))

    def distance_to(self, x: float, y: float) -> float:
        """Euclidean distance from this position to ``(x, y)`` (thesis equation 1)."""
        return math.hypot(x - self.x, y - self.y)

    def bearing_to(self, x: float, y: float) -> float:
        """Heading that faces ``(x, y)`` from here; this pose's heading if they coincide."""
        if x == self.x and y == self.y:
            return self.heading
        return normalize_angle(math.atan2(y - self.y, x - self.x))
