"""Phases of constant acceleration: the closed-form building block of speed profiles.

Every :class:`~cas_async.SpeedProfile` is a sequence of phases, and
within one phase distance is a quadratic in time (thesis equation 2), so both
distance and its inverse have closed forms. ``phase_starts``, ``locate`` and
``solve`` are shared by the profiles and by the vectorised segment table.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

from .._errors import SimulationError

__all__ = ["Phase", "check_phases", "locate", "phase_starts", "solve"]

# A ramp may end a hair below zero speed through rounding of its duration.
_SPEED_SLACK: Final = 1e-9


@dataclass(frozen=True, slots=True)
class Phase:
    """A stretch of constant acceleration.

    Attributes:
        duration: seconds; ``inf`` only for the final cruise.
        speed: speed at the start of the phase (distance units per second).
        acceleration: units per second squared; negative slows down.
    """

    duration: float
    speed: float
    acceleration: float

    def distance(self, tau: float) -> float:
        """Distance covered ``tau`` seconds into the phase (thesis equation 2)."""
        return tau * (self.speed + 0.5 * self.acceleration * tau)

    def speed_at(self, tau: float) -> float:
        """Speed ``tau`` seconds into the phase (never negative)."""
        return max(0.0, self.speed + self.acceleration * tau)


def check_phases(phases: Sequence[Phase]) -> tuple[Phase, ...]:
    """Checks the phase contract of :class:`SpeedProfile` and returns the phases.

    The contract: at least one phase; every phase starts at a finite speed
    ``>= 0`` with a finite acceleration; every phase but the last lasts a finite
    positive time and does not end below zero speed; the last is a cruise
    (``duration == inf``, ``acceleration == 0``, ``speed > 0``), so that any
    distance is eventually covered.

    Raises:
        SimulationError: naming the first phase that breaks the contract.
    """
    phases = tuple(phases)
    if not phases:
        raise SimulationError("a speed profile needs at least one phase")
    last = len(phases) - 1
    for index, phase in enumerate(phases):
        problem = _broken(phase, last=index == last)
        if problem is not None:
            raise SimulationError(f"phase {index} ({phase}): {problem}")
    return phases


def _broken(phase: Phase, *, last: bool) -> str | None:
    """What breaks the phase contract in ``phase`` (``None``: nothing)."""
    if not (math.isfinite(phase.speed) and phase.speed >= 0):
        return "speed must be finite and >= 0"
    if not math.isfinite(phase.acceleration):
        return "acceleration must be finite"
    if last:
        if not (phase.duration == math.inf and phase.acceleration == 0 and phase.speed > 0):
            return "the last phase must be a cruise (duration inf, acceleration 0, speed > 0)"
    elif not (math.isfinite(phase.duration) and phase.duration > 0):
        return "a ramp needs a finite duration > 0"
    elif phase.speed + phase.acceleration * phase.duration < -_SPEED_SLACK:
        return "the ramp ends below zero speed"
    return None


def phase_starts(phases: Sequence[Phase]) -> list[tuple[float, float, Phase]]:
    """Each phase with the time and the distance at which it begins."""
    table: list[tuple[float, float, Phase]] = []
    time = distance = 0.0
    for phase in phases:
        table.append((time, distance, phase))
        time += phase.duration
        distance += phase.distance(phase.duration) if math.isfinite(phase.duration) else 0.0
    return table


def locate(table: Sequence[tuple[float, float, Phase]], t: float) -> int:
    """Index of the phase in force at ``t``: the last one that starts at or before it."""
    found = 0
    for index, (start, _, _) in enumerate(table):
        if start > t:
            break
        found = index
    return found


def solve(speed: float, acceleration: float, distance: float) -> float:
    """Smallest ``tau >= 0`` with ``speed * tau + acceleration * tau**2 / 2 == distance``."""
    if distance <= 0:
        return 0.0
    # The quadratic formula in its cancellation-free form: stable as acceleration
    # tends to 0, where the textbook form divides two vanishing quantities.
    root = math.sqrt(max(0.0, speed * speed + 2.0 * acceleration * distance))
    return 2.0 * distance / (speed + root)
