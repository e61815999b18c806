"""The controller :class:`~cas_async.ros.RosDiffDrive` drives with: turn, drive, stop.

A differential-drive robot takes a linear speed ``v`` (forward, m/s) and a turn
rate ``ω`` (rad/s, counter-clockwise). On every odometry message the controller
answers the robot's pose with one command:

1. **Turn** toward the goal in place (``v = 0``) while the heading error ``e`` is
   above ``heading_tolerance``: ``ω = turn_gain · e``, at least ``min_turn_rate``
   and at most ``max_turn_rate`` in magnitude.
2. **Drive** once facing it: ``v = min(cruise, approach_gain · d) · cos e`` (it
   slows down within ``cruise / approach_gain`` metres, never below ``min_speed``)
   while ``ω = turn_gain · e`` corrects the drift. A heading error above
   ``realign`` (a push, or a goal passed) stops it to turn again.
3. **Stop** (``None``) once within ``position_tolerance`` of the goal.

Turning to a heading is step 1 alone, done within ``heading_tolerance``. The
defaults suit a TurtleBot-sized robot whose odometry comes at 20-50 Hz.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .. import ConfigurationError, Pose, normalize_angle

__all__ = ["DiffDriveController", "DriveTuning"]


@dataclass(frozen=True, slots=True)
class DriveTuning:
    """The controller's parameters (see the module docs for where each acts).

    Raises:
        ConfigurationError: a value that is not a finite number > 0, or a
            ``min_turn_rate`` above ``max_turn_rate``.
    """

    position_tolerance: float = 0.05
    """Metres from the goal at which a move is done."""
    heading_tolerance: float = 0.03
    """Radians from the wanted heading at which a turn is done."""
    max_turn_rate: float = 1.0
    """The fastest turn commanded, rad/s."""
    min_turn_rate: float = 0.1
    """The slowest turn commanded while turning in place, rad/s (so a turn ends)."""
    turn_gain: float = 2.0
    """Turn rate per radian of heading error, 1/s."""
    approach_gain: float = 1.0
    """Forward speed per metre left, 1/s: how early the robot slows down."""
    min_speed: float = 0.03
    """The slowest forward speed while driving, m/s (so a move ends)."""
    realign: float = 0.5
    """Radians of heading error at which driving stops to turn again."""

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if not (isinstance(value, int | float) and value > 0 and math.isfinite(value)):
                raise ConfigurationError(
                    f"DriveTuning.{name} must be a finite number > 0, got {value!r}"
                )
        if self.min_turn_rate > self.max_turn_rate:
            raise ConfigurationError(
                f"DriveTuning.min_turn_rate ({self.min_turn_rate}) is above max_turn_rate "
                f"({self.max_turn_rate})"
            )


class DiffDriveController:
    """One move's state (turning or driving) and its command for each pose.

    Args:
        tuning: the controller's parameters.
    """

    def __init__(self, tuning: DriveTuning | None = None) -> None:
        self.tuning = tuning if tuning is not None else DriveTuning()
        self.turning = True

    def reset(self) -> None:
        """Before a new move: it starts by turning."""
        self.turning = True

    def toward(self, pose: Pose, x: float, y: float, cruise: float) -> tuple[float, float] | None:
        """The command ``(v, ω)`` that brings ``pose`` to ``(x, y)``; ``None`` once there.

        ``cruise`` is the forward speed wanted now (m/s, the speed profile's).
        """
        t = self.tuning
        distance = pose.distance_to(x, y)
        if distance <= t.position_tolerance:
            return None
        error = normalize_angle(pose.bearing_to(x, y) - pose.heading)
        if self.turning and abs(error) <= t.heading_tolerance:
            self.turning = False
        elif not self.turning and abs(error) > t.realign:
            self.turning = True
        if self.turning:
            return 0.0, self._turn_rate(error)
        speed = max(t.min_speed, min(cruise, t.approach_gain * distance)) * math.cos(error)
        turn = max(-t.max_turn_rate, min(t.max_turn_rate, t.turn_gain * error))
        return speed, turn

    def facing(self, pose: Pose, heading: float) -> tuple[float, float] | None:
        """The command that turns ``pose`` in place to ``heading``; ``None`` once there."""
        error = normalize_angle(heading - pose.heading)
        if abs(error) <= self.tuning.heading_tolerance:
            return None
        return 0.0, self._turn_rate(error)

    def _turn_rate(self, error: float) -> float:
        t = self.tuning
        rate = max(t.min_turn_rate, min(t.max_turn_rate, t.turn_gain * abs(error)))
        return math.copysign(rate, error)
