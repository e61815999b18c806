"""Speed profiles: how fast a robot translates, as a function of time.

A profile is a sequence of :class:`~cas_async.sim.Phase` objects of
constant acceleration: any number of finite *ramps* followed by an unbounded
*cruise* at a positive speed. Time ``t`` is measured from the profile's
reference instant (for a move, the moment translation starts). Because every
phase is a quadratic in time, the distance ``distance(t)`` and its inverse
``time_for(d)`` have closed forms (the thesis's equations 2-5), and
:class:`~cas_async.sim._environment.Environment` can evaluate thousands of
robots' profiles at once with numpy.

To plug in a new profile, subclass :class:`SpeedProfile` and implement
``phases()``; override ``advanced()`` to keep your type when the profile ages.
Fatigue, for instance, is a :class:`Decelerating` profile that ages across moves.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Iterable
from dataclasses import dataclass, field

from .._errors import SimulationError
from ._phases import Phase, check_phases, locate, phase_starts, solve

__all__ = [
    "ConstantSpeed",
    "Decelerating",
    "PiecewiseSpeed",
    "SpeedProfile",
    "closing_time",
]


def _check_time(name: str, value: float) -> None:
    if not (value >= 0 and math.isfinite(value)):
        raise SimulationError(f"{name} must be a finite number >= 0, got {value!r}")


def closing_time(distance: float, profiles: Iterable[SpeedProfile]) -> float:
    """Time for robots to cover ``distance`` together, each under its own profile.

    With two profiles, this is when two robots driving straight at each other
    meet (thesis equation 3, including the minimum-speed case of equation 5);
    with one, it is :meth:`SpeedProfile.time_for` (equation 4). Each profile's
    time 0 is now; rotations are not included. Closed form: within each interval
    between phase boundaries the summed distance is one quadratic.

    Raises:
        SimulationError: ``distance`` is negative or not finite, or no profile.
    """
    _check_time("distance", distance)
    tables = [profile.starts() for profile in profiles]
    if not tables:
        raise SimulationError("closing_time needs at least one speed profile")
    if len(tables) == 1:
        return _time_for(distance, tables[0])
    if len(tables) == 2:
        return _meeting(distance, *tables)
    return _merged(distance, tables)


def _merged(distance: float, tables: list[Starts]) -> float:
    """:func:`closing_time` of any number of profiles' checked ``tables``."""
    bounds = sorted({start for table in tables for start, _, _ in table})
    last = len(bounds) - 1
    for index, begin in enumerate(bounds):
        end = bounds[index + 1] if index < last else math.inf
        current = [table[locate(table, begin)] for table in tables]
        if end < math.inf:
            reach = sum([d0 + phase.distance(end - t0) for t0, d0, phase in current])
            if reach < distance:
                continue
        covered = sum([d0 + phase.distance(begin - t0) for t0, d0, phase in current])
        speed = sum([phase.speed_at(begin - t0) for t0, _, phase in current])
        acceleration = sum([phase.acceleration for _, _, phase in current])
        return begin + min(solve(speed, acceleration, distance - covered), end - begin)
    raise AssertionError("unreachable: the last interval is an unbounded cruise")


def _meeting(distance: float, first: Starts, second: Starts) -> float:
    """:func:`_merged` of two tables (two robots meeting): the same arithmetic, unrolled.

    ``sum`` of two floats is ``0.0 + a + b``, in that order, on every Python.
    """
    bounds = sorted({start for start, _, _ in first} | {start for start, _, _ in second})
    last = len(bounds) - 1
    for index, begin in enumerate(bounds):
        end = bounds[index + 1] if index < last else math.inf
        t1, d1, one = first[locate(first, begin)]
        t2, d2, two = second[locate(second, begin)]
        if end < math.inf:
            reach = 0.0 + (d1 + one.distance(end - t1)) + (d2 + two.distance(end - t2))
            if reach < distance:
                continue
        covered = 0.0 + (d1 + one.distance(begin - t1)) + (d2 + two.distance(begin - t2))
        speed = 0.0 + one.speed_at(begin - t1) + two.speed_at(begin - t2)
        acceleration = 0.0 + one.acceleration + two.acceleration
        return begin + min(solve(speed, acceleration, distance - covered), end - begin)
    raise AssertionError("unreachable: the last interval is an unbounded cruise")


def _time_for(distance: float, table: Starts) -> float:
    """:func:`closing_time` of a single profile: the same arithmetic, figure for figure.

    With one table, the intervals are its phases: each begins where its phase
    starts (so a phase's own clock reads 0 there), and a phase that rounds to no
    time at all gives way to the next, which starts at the same instant.
    """
    last = len(table) - 1
    for index, (begin, covered, phase) in enumerate(table):
        end = table[index + 1][0] if index < last else math.inf
        if end == begin:
            continue
        covered += phase.distance(0.0)
        if end < math.inf and covered + phase.distance(end - begin) < distance:
            continue
        speed = phase.speed_at(0.0)
        return begin + min(solve(speed, phase.acceleration, distance - covered), end - begin)
    raise AssertionError("unreachable: the last phase is an unbounded cruise")


Starts = tuple[tuple[float, float, Phase], ...]
"""Each phase of a profile with the time and the distance at which it begins."""


class SpeedProfile(ABC):
    """Translation speed as a function of time since a reference instant.

    Subclasses implement :meth:`phases`; everything else is derived in closed
    form. Profiles are immutable values: ageing one returns a new profile.
    """

    __slots__ = ()

    @abstractmethod
    def phases(self) -> tuple[Phase, ...]:
        """The phases from time 0 on; they must satisfy :func:`check_phases`."""

    def starts(self) -> Starts:
        """Each phase with the time and the distance at which it begins.

        :func:`~cas_async._body._phases.phase_starts` of :meth:`phases`; the profiles of
        this module work it out once, on first use, as every question about a
        profile (its speed, distance, meeting time...) starts from it.
        """
        return tuple(phase_starts(self.phases()))

    def top_speed(self) -> float:
        """The fastest this profile ever goes: a phase's start, or a finite phase's end."""
        fastest = 0.0
        for phase in self.phases():
            fastest = max(fastest, phase.speed)
            if math.isfinite(phase.duration):
                fastest = max(fastest, phase.speed_at(phase.duration))
        return fastest

    def speed_at(self, t: float) -> float:
        """Speed ``t >= 0`` seconds after the reference instant."""
        _check_time("t", t)
        table = self.starts()
        start, _, phase = table[locate(table, t)]
        return phase.speed_at(t - start)

    def distance(self, t: float) -> float:
        """Distance covered between the reference instant and ``t >= 0``."""
        _check_time("t", t)
        table = self.starts()
        start, covered, phase = table[locate(table, t)]
        return covered + phase.distance(t - start)

    def time_for(self, distance: float) -> float:
        """The first instant at which ``distance`` has been covered (inverse of ``distance``)."""
        _check_time("distance", distance)
        return _time_for(distance, self.starts())

    def advanced(self, dt: float) -> SpeedProfile:
        """This profile as seen ``dt >= 0`` seconds later (what carries across moves)."""
        _check_time("dt", dt)
        if dt == 0:
            return self
        table = self.starts()
        index = locate(table, dt)
        start, _, phase = table[index]
        into = dt - start
        first = Phase(phase.duration - into, phase.speed_at(into), phase.acceleration)
        rest = tuple(later for _, _, later in table[index + 1 :])
        # A ramp whose remaining time rounds to nothing is dropped, not kept at zero length.
        return PiecewiseSpeed((first, *rest) if first.duration > 0 else rest)


@dataclass(frozen=True, slots=True)
class _KeepsStarts(SpeedProfile):
    """A profile of this module: its starts worked out on first use, and kept.

    ``_starts`` is left out of ``__init__``, equality, hash and repr, so a profile
    that has worked them out equals, hashes and prints as its fresh copy.
    """

    _starts: Starts | None = field(default=None, init=False, repr=False, compare=False)

    def starts(self) -> Starts:
        """As :meth:`SpeedProfile.starts`, worked out once (a frozen value: set once)."""
        starts = self._starts
        if starts is None:
            starts = tuple(phase_starts(self.phases()))
            object.__setattr__(self, "_starts", starts)
        return starts


@dataclass(frozen=True, slots=True)
class PiecewiseSpeed(_KeepsStarts):
    """Any profile given by its phases (see :func:`check_phases` for the contract)."""

    parts: tuple[Phase, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "parts", check_phases(self.parts))

    def phases(self) -> tuple[Phase, ...]:
        """The phases given at construction."""
        return self.parts


@dataclass(frozen=True, slots=True)
class ConstantSpeed(_KeepsStarts):
    """A constant speed: ``distance(t) = speed * t``.

    Raises:
        SimulationError: ``speed`` is not a finite number > 0.
    """

    speed: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise SimulationError(f"speed must be finite and > 0, got {self.speed!r}")

    def phases(self) -> tuple[Phase, ...]:
        """A single cruise."""
        return (Phase(math.inf, self.speed, 0.0),)

    def advanced(self, dt: float) -> ConstantSpeed:
        """The same profile: a constant speed does not age."""
        _check_time("dt", dt)
        return self


@dataclass(frozen=True, slots=True)
class Decelerating(_KeepsStarts):
    """Speed ``initial_speed - deceleration * t``, down to ``min_speed``, then constant.

    The thesis's fatigue of a robot carrying a load: it slows down steadily until
    it reaches a minimum speed (the minimum-velocity mode, equation 5), then keeps
    that speed. ``advanced(dt)`` returns the profile with the speed reached after
    ``dt`` seconds, so a move can start already slowed down.

    Attributes:
        initial_speed: speed at time 0, ``>= min_speed``.
        deceleration: slowdown per second, ``>= 0``.
        min_speed: the floor, ``> 0`` (a robot that could stop would never arrive).

    Raises:
        SimulationError: a value is not finite, ``min_speed <= 0``,
            ``deceleration < 0``, or ``min_speed > initial_speed``.
    """

    initial_speed: float
    deceleration: float
    min_speed: float

    def __post_init__(self) -> None:
        for name in ("initial_speed", "deceleration", "min_speed"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise SimulationError(f"{name} must be finite, got {value!r}")
        if self.min_speed <= 0:
            raise SimulationError(f"min_speed must be > 0, got {self.min_speed!r}")
        if self.deceleration < 0:
            raise SimulationError(f"deceleration must be >= 0, got {self.deceleration!r}")
        if self.min_speed > self.initial_speed:
            raise SimulationError(
                f"min_speed {self.min_speed!r} exceeds initial_speed {self.initial_speed!r}"
            )

    @property
    def floor_time(self) -> float:
        """Seconds until the minimum speed is reached (thesis equation 5); ``inf`` if never."""
        if self.initial_speed == self.min_speed:
            return 0.0
        if self.deceleration == 0:
            return math.inf
        return (self.initial_speed - self.min_speed) / self.deceleration

    def phases(self) -> tuple[Phase, ...]:
        """A decelerating ramp (unless already at the floor or not slowing) and a cruise."""
        ramp = self.floor_time
        if ramp == 0:
            return (Phase(math.inf, self.min_speed, 0.0),)
        if ramp == math.inf:
            return (Phase(math.inf, self.initial_speed, 0.0),)
        return (
            Phase(ramp, self.initial_speed, -self.deceleration),
            Phase(math.inf, self.min_speed, 0.0),
        )

    def advanced(self, dt: float) -> Decelerating:
        """The same slowdown, starting from the speed reached ``dt`` seconds later."""
        _check_time("dt", dt)
        speed = max(self.min_speed, self.initial_speed - self.deceleration * dt)
        if speed == self.initial_speed:
            return self
        return Decelerating(speed, self.deceleration, self.min_speed)
