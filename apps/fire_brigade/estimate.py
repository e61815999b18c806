"""The partner-time estimate of the Fire Brigade demo (thesis §5.2, equations 1-5).

A robot holding a bucket ranks its candidate partners by how soon the bucket
would reach the sink: the time for the two to meet, plus the time the partner
then needs to carry the bucket to the sink alone. The thesis solves one
quadratic per case (equations 2-4) and patches in the minimum-speed mode
(equation 5); here every case goes through :func:`cas_async.sim.closing_time`,
which already splits the motion at each profile's phase boundaries.

A profile of ``None`` stands for an immobile robot: a generator when it gives,
a sink when it receives. Everything here is a pure function of floats; each
profile's time 0 is the moment the estimate is made.
"""

from __future__ import annotations

import math
from typing import TypeAlias

from cas_async import SimulationError, SpeedProfile
from cas_async.sim import closing_time

__all__ = [
    "Point",
    "carrying_time",
    "delivery_time",
    "distance",
    "meeting_point",
    "meeting_time",
    "solo_time",
]

Point: TypeAlias = tuple[float, float]
"""A position in the plane, ``(x, y)``."""


def _check_gap(gap: float) -> None:
    if not (gap >= 0 and math.isfinite(gap)):
        raise SimulationError(f"gap must be a finite number >= 0, got {gap!r}")


def distance(a: Point, b: Point) -> float:
    """Euclidean distance between two points (equation 1)."""
    return math.hypot(b[0] - a[0], b[1] - a[1])


def meeting_time(gap: float, giver: SpeedProfile | None, receiver: SpeedProfile | None) -> float:
    """Time for two robots ``gap`` apart, driving straight at each other, to meet.

    With two mobile robots this is equation 3 (the sum of two instances of
    equation 2 equals the gap), generalised to any pair of profiles; with one
    immobile robot (``None``) only the other moves, which is equation 4. If a
    decelerating robot reaches its minimum speed before the meeting, the time
    until then (equation 5) plus the remaining gap at the summed speeds is what
    :func:`~cas_async.sim.closing_time` returns.

    Args:
        gap: distance between the two robots, ``>= 0``.
        giver: profile of the robot carrying the bucket, or ``None`` if immobile.
        receiver: profile of the empty robot, or ``None`` if immobile.

    Returns:
        Seconds until the two are at the same point; ``0.0`` for a zero gap.

    Raises:
        SimulationError: ``gap`` is negative or not finite (also a ``ValueError``).
        ValueError: both robots are immobile and the gap is positive.
    """
    _check_gap(gap)
    movers = tuple(profile for profile in (giver, receiver) if profile is not None)
    if not movers:
        if gap == 0:
            return 0.0
        raise ValueError("two immobile robots cannot meet")
    return closing_time(gap, movers)


def meeting_point(
    giver_at: Point,
    receiver_at: Point,
    giver: SpeedProfile | None,
    receiver: SpeedProfile | None,
) -> Point:
    """Where two robots driving straight at each other meet (equations 1-5).

    The giver covers ``giver.distance(meeting_time)`` of the segment from
    ``giver_at`` to ``receiver_at``. An immobile receiver is met where it stands
    (a sink), and an immobile giver is met where it stands (a generator).

    Raises:
        SimulationError: a coordinate is not finite.
        ValueError: both robots are immobile and apart.
    """
    return _meet(giver_at, receiver_at, giver, receiver)[1]


def _meet(
    giver_at: Point,
    receiver_at: Point,
    giver: SpeedProfile | None,
    receiver: SpeedProfile | None,
) -> tuple[float, Point]:
    """The meeting time and point, computed once for both public functions."""
    gap = distance(giver_at, receiver_at)
    time = meeting_time(gap, giver, receiver)
    # The immobile cases return an input point itself, not a recomputed one
    # that could differ from it in the last bit.
    if gap == 0 or giver is None:
        return time, giver_at
    if receiver is None:
        return time, receiver_at
    # Clamped because the giver's distance at the rounded meeting time may
    # overshoot the gap by an ulp.
    fraction = min(1.0, giver.distance(time) / gap)
    point = (
        giver_at[0] + fraction * (receiver_at[0] - giver_at[0]),
        giver_at[1] + fraction * (receiver_at[1] - giver_at[1]),
    )
    return time, point


def carrying_time(gap: float, profile: SpeedProfile) -> float:
    """Time for one robot to carry a bucket ``gap`` units under ``profile``.

    Equation 4, and, once the robot has slowed to its minimum speed, the time
    until then (equation 5) plus the rest of the way at the minimum speed.

    Raises:
        SimulationError: ``gap`` is negative or not finite.
    """
    _check_gap(gap)
    return profile.time_for(gap)


def delivery_time(
    giver_at: Point,
    giver: SpeedProfile | None,
    partner_at: Point,
    partner_empty: SpeedProfile | None,
    partner_loaded: SpeedProfile | None,
    sink_at: Point,
) -> float:
    """The thesis's partner metric: time until the bucket reaches the sink via this partner.

    The two meet (equation 3, or 4 if one is immobile, with equation 5's
    minimum-speed mode), then the partner carries the bucket from the meeting
    point to the sink alone (equation 4, with equation 5) under
    ``partner_loaded``, the profile it will have once it holds the bucket.
    A partner that is the sink itself (immobile, at ``sink_at``) costs the
    meeting time only.

    Args:
        giver_at: where the robot holding the bucket is.
        giver: its current profile, or ``None`` for a generator.
        partner_at: where the candidate partner is.
        partner_empty: the partner's profile while it drives to the meeting
            point, or ``None`` if it is immobile (a sink).
        partner_loaded: the partner's profile from the moment it holds the
            bucket, or ``None`` if it cannot carry one.
        sink_at: where the bucket must go.

    Returns:
        Seconds from now until the bucket is at the sink.

    Raises:
        ValueError: both robots are immobile and apart, or the meeting point is
            not the sink and the partner cannot carry (``partner_loaded`` is ``None``).
    """
    met, meet = _meet(giver_at, partner_at, giver, partner_empty)
    remaining = distance(meet, sink_at)
    if remaining == 0:
        return met
    if partner_loaded is None:
        raise ValueError(
            f"the partner at {partner_at!r} cannot carry the bucket from the meeting "
            f"point {meet!r} to the sink at {sink_at!r}: partner_loaded is None"
        )
    return met + carrying_time(remaining, partner_loaded)


def solo_time(giver_at: Point, giver: SpeedProfile, sink_at: Point) -> float:
    """Time for the giver to carry the bucket to the sink itself (equations 1, 4 and 5)."""
    return carrying_time(distance(giver_at, sink_at), giver)
