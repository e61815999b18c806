"""Where things go: the drop spots in the zone, the objects on the floor, and their checks.

Drop spots: the zone holds a square grid of spots, ``1.25 * largest size``
apart (so that objects put down side by side never overlap, with room between
them for a robot standing at a side: robots are points here), centred on the
zone's centre; a spot counts when an
object of the largest size put there lies wholly inside the zone. Spots are
handed out nearest the centre first, one per object, in object id order.
"""

from __future__ import annotations

import math

import numpy as np

from .config import BoxMovingConfig, ObjectSpec
from .geometry import Point, distance
from .records import Box

__all__ = ["drop_spots", "lift_problems", "place_objects", "spot_count"]

_SPACING = 1.25
"""Drop spots are this many times the largest object's size apart."""

_TRIES = 1000
"""Draws per scattered object before it is placed even if it overlaps another."""


def drop_spots(centre: Point, radius: float, largest: float, count: int) -> list[Point]:
    """The first ``count`` drop spots of the zone (module docs); fewer if it is too small."""
    spacing = _SPACING * largest
    reach = radius - largest / 2
    if reach < 0:
        return []
    steps = int(reach // spacing) if spacing > 0 else 0
    spots = [
        (centre[0] + i * spacing, centre[1] + j * spacing)
        for i in range(-steps, steps + 1)
        for j in range(-steps, steps + 1)
        if math.hypot(i * spacing, j * spacing) <= reach + 1e-9
    ]
    spots.sort(
        key=lambda p: (
            round(distance(centre, p), 9),
            math.atan2(p[1] - centre[1], p[0] - centre[0]),
        )
    )
    return spots[:count]


def spot_count(config: BoxMovingConfig) -> int:
    """How many drop spots the zone holds for the configured objects."""
    zone = config.destination
    return len(drop_spots(zone.at, zone.radius, config.largest_size, config.object_count))


def place_objects(config: BoxMovingConfig, rng: np.random.Generator) -> list[Box]:
    """Every object, ids from 1: the listed ones, then the scattered ones (drawn with ``rng``)."""
    specs = list(config.objects)
    scatter = config.scatter
    zone = config.destination
    for _ in range(scatter.count):
        size = float(rng.uniform(*scatter.size))
        weight = float(rng.uniform(*scatter.weight))
        spot: Point = (0.0, 0.0)
        for _ in range(_TRIES):
            x, y = (float(v) for v in rng.uniform(scatter.area_min, scatter.area_max))
            spot = (x, y)
            clear = all(
                distance(spot, (other.x, other.y)) > (size + other.size) * 0.75 for other in specs
            )
            if clear and distance(spot, zone.at) > zone.radius + size:
                break
        specs.append(ObjectSpec(spot[0], spot[1], round(weight, 1), round(size, 2)))
    spots = drop_spots(zone.at, zone.radius, config.largest_size, len(specs))
    return [
        Box(obj, spec.x, spec.y, spec.weight, spec.size, drop[0], drop[1])
        for obj, (spec, drop) in enumerate(zip(specs, spots, strict=True), start=1)
    ]


def lift_problems(config: BoxMovingConfig) -> list[tuple[str, str]]:
    """The objects no robot, nor any two, can lift, each by its key."""
    payloads = sorted((robot.payload for robot in config.robots), reverse=True)
    if not payloads:
        return []
    strongest = payloads[0] + (payloads[1] if len(payloads) > 1 else 0.0)
    who = "the two strongest robots lift" if len(payloads) > 1 else "the only robot lifts"
    problems = [
        (f"objects[{index}].weight", f"no two robots can lift {spec.weight:g}: {who} {strongest:g}")
        for index, spec in enumerate(config.objects)
        if spec.weight > strongest
    ]
    if config.scatter.count and config.scatter.weight[1] > strongest:
        problems.append(
            (
                "scatter.weight",
                f"no two robots can lift up to {config.scatter.weight[1]:g}: {who} {strongest:g}",
            )
        )
    return problems
