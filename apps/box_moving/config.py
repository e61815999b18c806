"""The box-moving scenario sections, validated by cas_async's scenario loader.

A scenario file has, besides ``app``, ``[run]``, ``[world]`` and ``[layers]``:

* ``[mission]``: how many objects must be moved;
* ``[destination]``: the drop zone (a disc);
* ``[[robots]]``: each robot: where it starts, its speed and its payload;
* ``[[objects]]``: each object: where it lies, its weight and size; and/or
* ``[scatter]``: objects placed at random (with the run's seed) in an area;
* ``[carrying]``: how a load slows a robot, how long lifting takes;
* ``[coordination]``: the legs of a joint carry and their synchronisation;
* ``[partners]``: how long to wait before asking again;
* ``[messaging]``: timeouts and retries of the questions robots ask each other;
* ``[floor]``: the tolerance of the Floor's invariant.

Defaults follow the thesis's §4.4 example (two robots, target five objects);
the choices where the thesis is silent are explained in this app's README.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cas_async.scenario import setting

__all__ = [
    "BoxMovingConfig",
    "Carrying",
    "CoordinationConfig",
    "Destination",
    "FloorConfig",
    "Messaging",
    "Mission",
    "ObjectSpec",
    "Partners",
    "RobotSpec",
    "Scatter",
]

Point = tuple[float, float]


@dataclass(frozen=True)
class Mission:
    """When the run is complete."""

    target: int = setting(5, ge=1, doc="objects to move to the destination (thesis: five)")


@dataclass(frozen=True)
class Destination:
    """The drop zone: every object has its own drop spot inside it."""

    at: Point = setting((9.0, 5.0), doc="the zone's centre, [x, y]")
    radius: float = setting(1.5, gt=0, doc="the zone's radius")


@dataclass(frozen=True)
class RobotSpec:
    """One robot (the robots get ids 1, 2, ... in the order listed)."""

    x: float = setting(doc="where it starts")
    y: float = setting(doc="where it starts")
    heading: float | None = setting(
        None, doc="radians, counter-clockwise from +x (absent: drawn at random with the seed)"
    )
    speed: float = setting(1.0, gt=0, doc="speed without a load, distance units per second")
    payload: float = setting(10.0, gt=0, doc="the weight it lifts alone")


@dataclass(frozen=True)
class ObjectSpec:
    """One object (ids 1, 2, ... in the order listed, then the scattered ones)."""

    x: float = setting(doc="its centre")
    y: float = setting(doc="its centre")
    weight: float = setting(gt=0, doc="payload units")
    size: float = setting(0.5, gt=0, doc="the side of its square footprint")


@dataclass(frozen=True)
class Scatter:
    """Objects placed at random, uniformly in an area, without overlapping."""

    count: int = setting(0, ge=0, doc="how many (0: none)")
    weight: Point = setting((2.0, 10.0), gt=0, doc="[min, max] weight, drawn uniformly")
    size: Point = setting((0.4, 0.8), gt=0, doc="[min, max] size, drawn uniformly")
    area_min: Point = setting((1.0, 1.0), doc="lower-left corner of the area")
    area_max: Point = setting((6.0, 9.0), doc="upper-right corner of the area")


@dataclass(frozen=True)
class Carrying:
    """How robots lift, carry and turn."""

    slowdown: float = setting(
        0.5, ge=0, lt=1, doc="fraction of its speed a robot loses at full payload"
    )
    lift_time: float = setting(1.0, ge=0, doc="seconds a lift takes")
    put_down_time: float = setting(1.0, ge=0, doc="seconds a put-down takes")
    turn_rate: float = setting(math.pi, gt=0, doc="radians per second when turning in place")


@dataclass(frozen=True)
class CoordinationConfig:
    """The joint carry's pace."""

    leg_length: float = setting(2.0, gt=0, doc="the longest leg of a joint carry")
    sync_margin: float = setting(
        0.2, gt=0, doc="seconds between the leader's Go and the start of the leg"
    )


@dataclass(frozen=True)
class Partners:
    """Retrying."""

    retry_interval: float = setting(
        2.0, gt=0, doc="seconds before asking for a partner, or scanning, again"
    )


@dataclass(frozen=True)
class Messaging:
    """Timeouts and retries of the questions robots ask each other."""

    timeout: float = setting(0.5, gt=0, doc="seconds to wait for an answer before asking again")
    retries: int = setting(6, ge=0, doc="times a question is asked again before giving up")


@dataclass(frozen=True)
class FloorConfig:
    """The Floor's invariant."""

    slack: float = setting(0.1, gt=0, doc="how far a robot may be from where the invariant puts it")


def _two_robots() -> tuple[RobotSpec, ...]:
    return (RobotSpec(1.0, 2.0, payload=10.0), RobotSpec(1.0, 8.0, payload=6.0))


@dataclass(frozen=True)
class BoxMovingConfig:
    """All of the box-moving sections."""

    mission: Mission = setting(default_factory=Mission)
    destination: Destination = setting(default_factory=Destination)
    robots: tuple[RobotSpec, ...] = setting(default_factory=_two_robots)
    objects: tuple[ObjectSpec, ...] = setting(default_factory=tuple)
    scatter: Scatter = setting(default_factory=Scatter)
    carrying: Carrying = setting(default_factory=Carrying)
    coordination: CoordinationConfig = setting(default_factory=CoordinationConfig)
    partners: Partners = setting(default_factory=Partners)
    messaging: Messaging = setting(default_factory=Messaging)
    floor: FloorConfig = setting(default_factory=FloorConfig)

    @property
    def object_count(self) -> int:
        """Objects listed and scattered."""
        return len(self.objects) + self.scatter.count

    @property
    def largest_size(self) -> float:
        """The largest size an object may have (listed or scattered)."""
        sizes = [spec.size for spec in self.objects]
        if self.scatter.count:
            sizes.append(self.scatter.size[1])
        return max(sizes, default=0.0)
