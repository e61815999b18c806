"""The plane geometry of boxes: their sides, where a robot stands to lift one, and legs.

An object is a square of side ``size`` centred on its position, its edges
parallel to the axes. A robot lifts it standing at the middle of one edge, its
*side point*: half the size from the centre, toward that side. A joint carry
is walked in *legs*: equal straight pieces of the way from where the object
lies to its drop spot, each ending with both robots synchronised again.
"""

from __future__ import annotations

import math
from typing import Final

from .messages import Side

__all__ = ["Point", "distance", "legs", "nearest_side", "side_offset", "side_point"]

Point = tuple[float, float]

_DIRECTIONS: Final = {
    Side.WEST: (-1.0, 0.0),
    Side.EAST: (1.0, 0.0),
    Side.SOUTH: (0.0, -1.0),
    Side.NORTH: (0.0, 1.0),
}


def distance(a: Point, b: Point) -> float:
    """The straight-line distance between two points."""
    return math.hypot(b[0] - a[0], b[1] - a[1])


def side_offset(side: Side, size: float) -> Point:
    """Where a robot lifting from ``side`` stands, relative to the object's centre."""
    dx, dy = _DIRECTIONS[side]
    return (dx * size / 2, dy * size / 2)


def side_point(centre: Point, side: Side, size: float) -> Point:
    """Where a robot stands to lift an object of ``size`` at ``centre`` from ``side``."""
    dx, dy = side_offset(side, size)
    return (centre[0] + dx, centre[1] + dy)


def nearest_side(robot: Point, centre: Point, size: float) -> tuple[Side, float]:
    """The side whose side point is nearest ``robot``, and how far it is.

    Ties go to the first side in :class:`Side` order (west, east, south, north),
    so the answer never depends on rounding in a way two robots could disagree on.
    """
    best = min(Side, key=lambda side: (distance(robot, side_point(centre, side, size)), side))
    return best, distance(robot, side_point(centre, best, size))


def legs(start: Point, end: Point, leg_length: float) -> list[Point]:
    """The ends of the legs from ``start`` to ``end``: equal pieces no longer than ``leg_length``.

    At least one leg, the last ending exactly at ``end``.
    """
    count = max(1, math.ceil(distance(start, end) / leg_length - 1e-9))
    dx, dy = end[0] - start[0], end[1] - start[1]
    ends = [(start[0] + dx * k / count, start[1] + dy * k / count) for k in range(1, count)]
    return [*ends, end]
