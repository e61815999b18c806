"""Closed-form motions of a 2-D mobile robot: rotate in place, then drive straight.

A :class:`Motion` is a plan that starts at elapsed time 0 from a :class:`Pose`:

1. rotate in place, the short way round, at a constant turn rate;
2. translate along a straight line under a :class:`SpeedProfile`.

Its durations come from closed-form kinematics (no integration), and
:meth:`Motion.pose_at` gives the exact pose at any elapsed time, during the
rotation, during the translation, or after. Headings follow :mod:`.pose`:
radians counter-clockwise from +x in ``(-pi, pi]``; a half turn is made
counter-clockwise.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from .._body._phases import Phase, check_phases
from .._body._pose import Pose, normalize_angle
from .._body._profiles import PiecewiseSpeed, SpeedProfile
from .._errors import SimulationError

__all__ = ["Motion", "check_turn_rate"]


_PROFILES_KEPT: Final = 1024
"""At most this many profiles :meth:`Motion.from_numbers` keeps (a swarm uses a few dozen)."""
_profiles: dict[bytes, PiecewiseSpeed] = {}  # by their phases' bits: -0.0 is not 0.0


def _profile_of(numbers: list[float]) -> PiecewiseSpeed:
    """The profile of these phase numbers (3 per phase), the same object for the same bits.

    Motions of a swarm share a few profiles (scale_250: 17 for 3,879 translations),
    and a profile is a frozen value: building and checking it once is enough.

    Raises:
        SimulationError: the phases break the profile contract.
    """
    key = struct.pack(f"{len(numbers)}d", *numbers)
    profile = _profiles.get(key)
    if profile is None:
        phases = (Phase(*numbers[i : i + 3]) for i in range(0, len(numbers), 3))
        profile = PiecewiseSpeed(tuple(phases))
        if len(_profiles) < _PROFILES_KEPT:
            _profiles[key] = profile
    return profile


def check_turn_rate(turn_rate: float) -> float:
    """Returns ``turn_rate`` (radians per second) if it is ``> 0``; ``inf`` turns instantly.

    Raises:
        SimulationError: ``turn_rate`` is NaN or not positive.
    """
    if not turn_rate > 0:  # also refuses NaN
        raise SimulationError(f"turn_rate must be > 0 rad/s (inf: instant), got {turn_rate!r}")
    return float(turn_rate)


def _rotation(start: Pose, heading: float, turn_rate: float) -> tuple[float, float]:
    """The signed turn from ``start`` to ``heading`` and the time it takes."""
    turn = normalize_angle(heading - start.heading)
    return turn, abs(turn) / check_turn_rate(turn_rate)


@dataclass(frozen=True, slots=True)
class Motion:
    """A rotation in place followed by a straight translation, from elapsed time 0.

    Build one with :meth:`standing`, :meth:`turn_to` or :meth:`straight_to`; the
    fields are consistent by construction.

    Attributes:
        start: pose at elapsed time 0.
        end: pose once the motion is over; a translation ends exactly on its target.
        turn: signed rotation made first, radians (counter-clockwise positive).
        rotation_time: seconds spent rotating.
        length: distance translated.
        translation_time: seconds spent translating.
        profile: the speed profile of the translation (``None`` when ``length == 0``);
            its time 0 is the start of the translation.
    """

    start: Pose
    end: Pose
    turn: float
    rotation_time: float
    length: float
    translation_time: float
    profile: SpeedProfile | None

    @classmethod
    def standing(cls, pose: Pose) -> Motion:
        """Not moving at all: the robot stays at ``pose``."""
        return cls(pose, pose, 0.0, 0.0, 0.0, 0.0, None)

    @classmethod
    def turn_to(cls, start: Pose, heading: float, *, turn_rate: float) -> Motion:
        """Rotate in place from ``start`` to face ``heading``, the short way round.

        Raises:
            SimulationError: ``heading`` is not finite or ``turn_rate`` is not positive.
        """
        end = Pose(start.x, start.y, heading)
        turn, rotation_time = _rotation(start, end.heading, turn_rate)
        return cls(start, end, turn, rotation_time, 0.0, 0.0, None)

    @classmethod
    def straight_to(
        cls, start: Pose, x: float, y: float, *, turn_rate: float, profile: SpeedProfile
    ) -> Motion:
        """Face ``(x, y)``, then drive to it under ``profile``; ends facing the way it drove.

        A target equal to the start position is a zero-length motion that keeps the
        heading.

        Raises:
            SimulationError: the target is not finite, ``turn_rate`` is not
                positive, or ``profile`` breaks the phase contract.
        """
        target = Pose(x, y, start.heading)  # validates the coordinates
        check_turn_rate(turn_rate)
        length = start.distance_to(target.x, target.y)
        if length == 0:
            return cls.standing(start)
        check_phases(profile.phases())
        end = Pose(target.x, target.y, start.bearing_to(target.x, target.y))
        turn, rotation_time = _rotation(start, end.heading, turn_rate)
        return cls(start, end, turn, rotation_time, length, profile.time_for(length), profile)

    def to_numbers(self) -> list[float]:
        """The motion as plain numbers, for :meth:`from_numbers` in another process.

        The profile travels as its phases: exactly what evaluating a pose needs.
        """
        numbers = [
            self.start.x,
            self.start.y,
            self.start.heading,
            self.end.x,
            self.end.y,
            self.end.heading,
            self.turn,
            self.rotation_time,
            self.length,
            self.translation_time,
        ]
        if self.profile is not None:
            for phase in self.profile.phases():
                numbers += (phase.duration, phase.speed, phase.acceleration)
        return numbers

    @classmethod
    def from_numbers(cls, numbers: Sequence[float]) -> Motion:
        """The motion :meth:`to_numbers` gave, exact to the bit.

        Raises:
            SimulationError: the numbers do not describe a motion.
        """
        if len(numbers) < 10 or (len(numbers) - 10) % 3:
            raise SimulationError(f"a motion is 10 numbers and 3 per phase, got {len(numbers)}")
        values = [float(n) for n in numbers]
        turn, rotation_time, length, translation_time = values[6:10]
        return cls(
            Pose(*values[0:3]),
            Pose(*values[3:6]),
            turn,
            rotation_time,
            length,
            translation_time,
            _profile_of(values[10:]) if len(values) > 10 else None,
        )

    @property
    def duration(self) -> float:
        """Seconds from start to end: rotation then translation."""
        return self.rotation_time + self.translation_time

    def translating_time(self, elapsed: float) -> float:
        """Seconds spent translating by ``elapsed`` (how much the profile has aged)."""
        return min(max(0.0, elapsed - self.rotation_time), self.translation_time)

    def travelled(self, elapsed: float) -> float:
        """Distance along the line covered by ``elapsed``, in ``[0, length]``."""
        tau = self.translating_time(elapsed)
        if self.profile is None or tau <= 0:
            return 0.0
        if tau >= self.translation_time:
            return self.length
        return min(self.profile.distance(tau), self.length)

    def pose_at(self, elapsed: float) -> Pose:
        """The exact pose ``elapsed`` seconds after the start.

        Before 0 it is ``start``; from ``duration`` on it is ``end``.

        Raises:
            SimulationError: ``elapsed`` is NaN.
        """
        if math.isnan(elapsed):
            raise SimulationError("elapsed time must be a number, got nan")
        if elapsed <= 0:
            return self.start
        if elapsed >= self.duration:
            return self.end
        if elapsed < self.rotation_time:
            # Constant turn rate: the heading is a linear interpolation of the turn.
            fraction = elapsed / self.rotation_time
            return Pose(self.start.x, self.start.y, self.start.heading + self.turn * fraction)
        # Interpolating towards the end point (rather than stepping along the
        # heading) is what the vectorised Environment does too, so both agree.
        share = self.travelled(elapsed) / self.length
        return Pose(
            self.start.x + share * (self.end.x - self.start.x),
            self.start.y + share * (self.end.y - self.start.y),
            self.end.heading,
        )
