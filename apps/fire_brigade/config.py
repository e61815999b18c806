"""The Fire Brigade's scenario sections, validated by cas_async's scenario loader.

A scenario file has, besides ``app``, ``[run]`` and ``[world]``:

* ``[mission]``: how many buckets must reach a sink;
* ``[stations]``: where the Generators and Sinks stand;
* ``[transporters]``: how many, where they start, and how they move;
* ``[strategy]``: how partners are chosen, and the search parameters;
* ``[messaging]``: how the layers live with a lossy network (timeouts, retries).

Defaults follow the thesis's §5.8.1 scenario; the choices where the thesis is
silent are explained in this app's README.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from cas_async.scenario import setting

__all__ = [
    "FireBrigadeConfig",
    "Messaging",
    "Mission",
    "Stations",
    "StrategyConfig",
    "Transporters",
]

Point = tuple[float, float]


@dataclass(frozen=True)
class Mission:
    """When the run is complete."""

    buckets: int = setting(20, ge=1, doc="buckets to deliver to sinks")


@dataclass(frozen=True)
class Stations:
    """The immobile robots: Generators (make buckets) and Sinks (receive them)."""

    generators: tuple[Point, ...] = setting(((4.0, 0.0), (8.0, 0.0)), doc="positions")
    sinks: tuple[Point, ...] = setting(((4.0, 9.0), (8.0, 9.0)), doc="positions")
    repeat: int = setting(
        1, ge=1, doc="copies of the whole layout of stations, for large swarms (1: as listed)"
    )
    repeat_offset: Point = setting(
        (10.0, 0.0), doc="each copy stands this far from the previous one, [dx, dy]"
    )

    def placed(self, points: tuple[Point, ...]) -> tuple[Point, ...]:
        """``points`` (``generators`` or ``sinks``) in every copy: copy by copy, in listed order."""
        dx, dy = self.repeat_offset
        return tuple((x + k * dx, y + k * dy) for k in range(self.repeat) for x, y in points)


@dataclass(frozen=True)
class Transporters:
    """The mobile robots and their physics."""

    count: int = setting(16, ge=1, doc="how many transporters")
    spawn_min: Point = setting((3.0, 1.0), doc="lower-left corner of the spawn area")
    spawn_max: Point = setting((9.0, 7.0), doc="upper-right corner of the spawn area")
    speed: float = setting(5.0, gt=0, doc="full speed, distance units per second")
    deceleration: float = setting(1.0, ge=0, doc="slowdown per second while carrying")
    min_speed: float = setting(1.0, gt=0, doc="speed floor while carrying")
    turn_rate: float = setting(math.pi, gt=0, doc="radians per second when turning in place")
    handover_time: float = setting(0.5, ge=0, doc="seconds a hand-over takes")


@dataclass(frozen=True)
class StrategyConfig:
    """Partner selection: the Strategy layer used, and its search parameters."""

    name: str = setting(
        "time",
        doc="time, time_gain, sink_first, random, solo, or 'module:Class' (a Strategy subclass)",
    )
    range: float = setting(5.0, gt=0, doc="partners are looked for within this distance")
    search_step: float = setting(
        1.0, gt=0, doc="how far a carrier moves toward its sink before looking again"
    )
    retry_interval: float = setting(
        1.0, gt=0, doc="seconds a generator waits before asking again when all refused"
    )
    search_growth: float = setting(
        2.0, gt=1, doc="a generator widens its search radius by this factor per failed round"
    )
    sink_search: Literal["everyone", "nearby"] = setting(
        "everyone",
        doc="a generator asks every robot where the sinks are, or those within range first",
    )


@dataclass(frozen=True)
class Messaging:
    """Timeouts and retries: how long a layer waits for another robot before acting alone."""

    timeout: float = setting(
        0.5, gt=0, doc="seconds to wait for an answer (or a partner's sign) before asking again"
    )
    retries: int = setting(
        6, ge=0, doc="times a question is asked again before the partner counts as silent"
    )
    patience: float = setting(
        30.0, gt=0, doc="seconds a robot waits at a meeting point for a silent partner"
    )


@dataclass(frozen=True)
class FireBrigadeConfig:
    """All of the Fire Brigade's sections."""

    mission: Mission = setting(default_factory=Mission)
    stations: Stations = setting(default_factory=Stations)
    transporters: Transporters = setting(default_factory=Transporters)
    strategy: StrategyConfig = setting(default_factory=StrategyConfig)
    messaging: Messaging = setting(default_factory=Messaging)
