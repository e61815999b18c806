"""The Fire Brigade partner-time estimate (thesis §5.2, equations 1-5), checked by hand.

Every expected value is worked out in a comment next to it. Notation: a profile
``Decelerating(v, a, v_min)`` covers ``v*t - a*t**2/2`` until it reaches ``v_min``
at ``t_floor = (v - v_min) / a`` (equation 5), then ``v_min`` per second.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from apps.fire_brigade.estimate import (
    Point,
    carrying_time,
    delivery_time,
    distance,
    meeting_point,
    meeting_time,
    solo_time,
)
from cas_async import ConstantSpeed, Decelerating, SimulationError, SpeedProfile

REL = 1e-9

# The fatigue profile of most cases: v = 3, a = 0.5, v_min = 1, so
# t_floor = (3 - 1) / 0.5 = 4 s, by which time it has covered 3*4 - 0.25*16 = 8.
TIRED = Decelerating(initial_speed=3.0, deceleration=0.5, min_speed=1.0)
# The thesis's scenario-1 numbers (speed 5, deceleration 1) with a floor of 1:
# t_floor = (5 - 1) / 1 = 4 s, by which time it has covered 5*4 - 16/2 = 12.
FRESH = Decelerating(initial_speed=5.0, deceleration=1.0, min_speed=1.0)
EMPTY = ConstantSpeed(3.0)

# Equation 3 with TIRED giving to EMPTY over a gap of 5:
#   (3t - 0.25t²) + 3t = 5  ->  0.25t² - 6t + 5 = 0  ->  t² - 24t + 20 = 0
#   t = (24 - sqrt(576 - 80)) / 2 = 12 - sqrt(124) = 12 - 2*sqrt(31) ≈ 0.8644712743
# The other root (≈ 23.1) is past the floor and meaningless. At t ≈ 0.864 the
# giver still runs at 3 - 0.5*0.864 ≈ 2.57 > 1: no minimum-speed mode yet.
T_GAP5 = 12.0 - 2.0 * math.sqrt(31.0)


# --- equation 1 -------------------------------------------------------------------


@pytest.mark.parametrize(
    ("a", "b", "expected"),
    [
        ((0.0, 0.0), (3.0, 4.0), 5.0),  # the 3-4-5 triangle
        ((1.0, 2.0), (4.0, 6.0), 5.0),  # the same triangle, shifted: dx = 3, dy = 4
        ((-3.0, 0.0), (0.0, -4.0), 5.0),  # and reflected
        ((2.0, 2.0), (2.0, 2.0), 0.0),
    ],
    ids=["origin", "shifted", "reflected", "same-point"],
)
def test_distance_is_euclidean(a: Point, b: Point, expected: float) -> None:
    assert distance(a, b) == pytest.approx(expected, rel=REL)
    assert distance(b, a) == pytest.approx(expected, rel=REL)


# --- equations 3 and 4: meeting times -------------------------------------------


@pytest.mark.parametrize(
    ("gap", "giver", "receiver", "expected"),
    [
        # Equation 3 at constant speeds: 3t + 3t = 9  ->  t = 9 / 6 = 1.5.
        (9.0, ConstantSpeed(3.0), ConstantSpeed(3.0), 1.5),
        # Equation 3 with a decelerating giver: see T_GAP5 above.
        (5.0, TIRED, EMPTY, T_GAP5),
        # Equation 4 (receiver immobile, a sink): FRESH alone covers 4:
        #   5t - t²/2 = 4  ->  t² - 10t + 8 = 0  ->  t = 5 - sqrt(17) ≈ 0.8768943744
        # (< t_floor = 4 s, so on the ramp).
        (4.0, FRESH, None, 5.0 - math.sqrt(17.0)),
        # Equation 4 with the giver immobile (a generator): the receiver alone, 6 / 3 = 2.
        (6.0, None, EMPTY, 2.0),
        # Equation 5 regime: TIRED reaches v_min at t = 4 s, having covered 8 while
        # EMPTY covered 3*4 = 12; together 20 of 26. The remaining 6 close at
        # 1 + 3 = 4 per second: 6 / 4 = 1.5 s more, so t = 4 + 1.5 = 5.5.
        (26.0, TIRED, EMPTY, 5.5),
        # Exactly at the floor instant: 8 + 12 = 20  ->  t = 4.
        (20.0, TIRED, EMPTY, 4.0),
        # A giver already at its minimum speed (v = v_min = 1): 1t + 3t = 8  ->  t = 2.
        (8.0, Decelerating(1.0, 0.5, 1.0), EMPTY, 2.0),
        # The same giver reached by ageing TIRED 6 s: speed max(1, 3 - 0.5*6) = 1.
        (8.0, TIRED.advanced(6.0), EMPTY, 2.0),
        # A giver part-way down its ramp: TIRED aged 2 s is Decelerating(2, 0.5, 1),
        # t_floor = (2 - 1) / 0.5 = 2 s, covering 2*2 - 0.25*4 = 3 while EMPTY covers 6.
        # Gap 13: 13 - 9 = 4 left at 1 + 3 = 4 per second -> t = 2 + 1 = 3.
        (13.0, TIRED.advanced(2.0), EMPTY, 3.0),
        # A zero gap: they have already met.
        (0.0, TIRED, EMPTY, 0.0),
        (0.0, None, None, 0.0),
    ],
    ids=[
        "eq3-constant",
        "eq3-decelerating-giver",
        "eq4-sink-receiver",
        "eq4-generator-giver",
        "eq5-floor-then-cruise",
        "eq5-floor-instant",
        "giver-already-at-floor",
        "giver-aged-to-floor",
        "giver-aged-mid-ramp",
        "zero-gap",
        "zero-gap-immobile",
    ],
)
def test_meeting_time(
    gap: float, giver: SpeedProfile | None, receiver: SpeedProfile | None, expected: float
) -> None:
    assert meeting_time(gap, giver, receiver) == pytest.approx(expected, rel=REL, abs=1e-12)


def test_meeting_time_is_symmetric_in_the_two_robots() -> None:
    # Closing a gap does not depend on who carries: same sum of distances.
    assert meeting_time(26.0, EMPTY, TIRED) == pytest.approx(5.5, rel=REL)


def test_two_immobile_robots_apart_cannot_meet() -> None:
    with pytest.raises(ValueError, match="two immobile robots cannot meet"):
        meeting_time(1.0, None, None)


@pytest.mark.parametrize("gap", [-1.0, math.inf, math.nan], ids=["negative", "inf", "nan"])
def test_a_bad_gap_is_named(gap: float) -> None:
    with pytest.raises(SimulationError, match="gap must be a finite number >= 0"):
        meeting_time(gap, TIRED, EMPTY)
    with pytest.raises(SimulationError, match="gap must be a finite number >= 0"):
        carrying_time(gap, TIRED)


# --- equations 4 and 5: carrying alone -------------------------------------------


@pytest.mark.parametrize(
    ("gap", "profile", "expected"),
    [
        # Equation 4 on the ramp: 5 - sqrt(17), as in the meeting-time table.
        (4.0, FRESH, 5.0 - math.sqrt(17.0)),
        # 3t - 0.25t² = 5  ->  t² - 12t + 20 = 0  ->  t = 2 (the other root, 10, is past the floor).
        (5.0, TIRED, 2.0),
        # Across the floor: 8 covered by t = 4 s, the other 2 at v_min = 1: t = 4 + 2 = 6.
        (10.0, TIRED, 6.0),
        # Entirely past the floor: TIRED aged 5 s runs at max(1, 3 - 2.5) = 1, so 7 / 1 = 7.
        (7.0, TIRED.advanced(5.0), 7.0),
        # Constant speed: 12 / 3 = 4.
        (12.0, EMPTY, 4.0),
        (0.0, TIRED, 0.0),
    ],
    ids=[
        "eq4-ramp",
        "eq4-ramp-integer-root",
        "eq5-across-floor",
        "eq5-entirely-at-floor",
        "constant",
        "zero",
    ],
)
def test_carrying_time(gap: float, profile: SpeedProfile, expected: float) -> None:
    assert carrying_time(gap, profile) == pytest.approx(expected, rel=REL, abs=1e-12)


def test_solo_time_carries_the_straight_line_to_the_sink() -> None:
    # Distance (0,0) -> (6,8) is 10 (a 6-8-10 triangle); TIRED needs 4 + 2/1 = 6 s for 10.
    assert solo_time((0.0, 0.0), TIRED, (6.0, 8.0)) == pytest.approx(6.0, rel=REL)


# --- meeting points ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("giver_at", "receiver_at", "giver", "receiver", "expected"),
    [
        # Equal constant speeds meet at the midpoint of (0,0)-(4,2): (2, 1).
        ((0.0, 0.0), (4.0, 2.0), ConstantSpeed(2.0), ConstantSpeed(2.0), (2.0, 1.0)),
        # Speeds 1 and 3 over 8: t = 8 / 4 = 2, the giver covers 1*2 = 2 -> (2, 0).
        ((0.0, 0.0), (8.0, 0.0), ConstantSpeed(1.0), ConstantSpeed(3.0), (2.0, 0.0)),
        # TIRED giving to EMPTY over 5: the receiver covers 3t, so the giver stops at
        # 5 - 3t = 5 - 3(12 - 2√31) = 6√31 - 31 ≈ 2.4065862 along the x axis.
        ((0.0, 0.0), (5.0, 0.0), TIRED, EMPTY, (6.0 * math.sqrt(31.0) - 31.0, 0.0)),
        # An immobile receiver (a sink) is met where it stands.
        ((0.0, 0.0), (3.0, 4.0), TIRED, None, (3.0, 4.0)),
        # An immobile giver (a generator) is met where it stands.
        ((1.0, 1.0), (4.0, 5.0), None, EMPTY, (1.0, 1.0)),
        # Already together.
        ((2.0, 3.0), (2.0, 3.0), TIRED, EMPTY, (2.0, 3.0)),
        ((2.0, 3.0), (2.0, 3.0), None, None, (2.0, 3.0)),
    ],
    ids=[
        "midpoint",
        "unequal-speeds",
        "decelerating-giver",
        "sink-receiver",
        "generator-giver",
        "same-point",
        "same-point-immobile",
    ],
)
def test_meeting_point(
    giver_at: Point,
    receiver_at: Point,
    giver: SpeedProfile | None,
    receiver: SpeedProfile | None,
    expected: Point,
) -> None:
    point = meeting_point(giver_at, receiver_at, giver, receiver)
    assert point == pytest.approx(expected, rel=REL, abs=1e-12)


def test_immobile_robots_are_met_at_exactly_their_position() -> None:
    # Not a recomputed point that could be off by an ulp.
    assert meeting_point((0.1, 0.2), (0.7, 0.3), TIRED, None) == (0.7, 0.3)
    assert meeting_point((0.1, 0.2), (0.7, 0.3), None, EMPTY) == (0.1, 0.2)


def test_two_immobile_robots_apart_have_no_meeting_point() -> None:
    with pytest.raises(ValueError, match="two immobile robots cannot meet"):
        meeting_point((0.0, 0.0), (1.0, 0.0), None, None)


# --- the partner metric -----------------------------------------------------------


@pytest.mark.parametrize(
    ("giver_at", "giver", "partner_at", "partner_empty", "partner_loaded", "sink_at", "expected"),
    [
        # Constant speeds: giver 2, partner 1 over a gap of 6 -> t = 6 / 3 = 2, meeting at
        # (4, 0). Sink at (4, 3): 3 more at the loaded speed 4 -> 0.75 s. Total 2.75.
        (
            (0.0, 0.0),
            ConstantSpeed(2.0),
            (6.0, 0.0),
            ConstantSpeed(1.0),
            ConstantSpeed(4.0),
            (4.0, 3.0),
            2.75,
        ),
        # TIRED gives to EMPTY 5 away, which then carries as a fresh TIRED to (20, 0).
        # Meet at t = 12 - 2√31 ≈ 0.8645, at x = 5 - 3t ≈ 2.4066 (see meeting points).
        # Remaining 20 - (5 - 3t) = 15 + 3t ≈ 17.59 > 8, so the carrier hits its floor:
        # carry = 4 + (15 + 3t - 8) / 1 = 11 + 3t. Total t + 11 + 3t = 11 + 4t
        # = 59 - 8√31 ≈ 14.4578851.
        ((0.0, 0.0), TIRED, (5.0, 0.0), EMPTY, TIRED, (20.0, 0.0), 59.0 - 8.0 * math.sqrt(31.0)),
        # A generator (immobile) gives to EMPTY 6 away: t = 6 / 3 = 2, met at (0, 0).
        # The partner then carries 10 as FRESH: 5t - t²/2 = 10 -> t² - 10t + 20 = 0
        # -> t = 5 - √5 ≈ 2.7639 (< t_floor = 4). Total 2 + 5 - √5 = 7 - √5.
        ((0.0, 0.0), None, (6.0, 0.0), EMPTY, FRESH, (10.0, 0.0), 7.0 - math.sqrt(5.0)),
        # The partner is the sink: meeting time only, TIRED carrying 5 -> t = 2 (as above).
        ((0.0, 0.0), TIRED, (5.0, 0.0), None, None, (5.0, 0.0), 2.0),
    ],
    ids=["constant-2d", "tired-chain", "generator-giver", "partner-is-sink"],
)
def test_delivery_time(
    giver_at: Point,
    giver: SpeedProfile | None,
    partner_at: Point,
    partner_empty: SpeedProfile | None,
    partner_loaded: SpeedProfile | None,
    sink_at: Point,
    expected: float,
) -> None:
    got = delivery_time(giver_at, giver, partner_at, partner_empty, partner_loaded, sink_at)
    assert got == pytest.approx(expected, rel=REL)


def test_handing_to_the_sink_costs_what_carrying_there_alone_costs() -> None:
    giver_at, sink_at = (1.0, 1.0), (7.0, 9.0)
    via_sink = delivery_time(giver_at, TIRED, sink_at, None, None, sink_at)
    assert via_sink == pytest.approx(solo_time(giver_at, TIRED, sink_at), rel=REL)


def test_a_partner_that_cannot_carry_away_from_the_sink_is_refused() -> None:
    with pytest.raises(ValueError, match="cannot carry the bucket"):
        delivery_time((0.0, 0.0), TIRED, (5.0, 0.0), None, None, (9.0, 0.0))


def test_a_partner_nearer_the_sink_beats_a_farther_one_at_the_same_gap() -> None:
    # Giver at the origin, sink at (10, 0); three partners 5 away with equal profiles.
    # All meet after the same t ≈ 0.8645, at 2.4066 from the giver toward the partner,
    # so the carry left is about 7.59 (ahead), 10.29 (beside), 12.41 (behind).
    giver_at, sink_at = (0.0, 0.0), (10.0, 0.0)

    def via(partner_at: Point) -> float:
        return delivery_time(giver_at, TIRED, partner_at, EMPTY, TIRED, sink_at)

    ahead, beside, behind = via((5.0, 0.0)), via((0.0, 5.0)), via((-5.0, 0.0))
    assert ahead < beside < behind


# --- properties -------------------------------------------------------------------

speeds = st.floats(min_value=0.1, max_value=10.0)
gaps = st.floats(min_value=0.0, max_value=1000.0)
coords = st.floats(min_value=-100.0, max_value=100.0)


@st.composite
def fatigue(draw: st.DrawFn) -> Decelerating:
    floor = draw(speeds)
    return Decelerating(
        initial_speed=floor + draw(st.floats(min_value=0.0, max_value=10.0)),
        deceleration=draw(st.floats(min_value=0.0, max_value=2.0)),
        min_speed=floor,
    )


@given(gap=gaps, giver=fatigue(), slow=speeds, fast=speeds)
def test_a_faster_receiver_never_meets_later(
    gap: float, giver: Decelerating, slow: float, fast: float
) -> None:
    slow, fast = sorted((slow, fast))
    with_fast = meeting_time(gap, giver, ConstantSpeed(fast))
    with_slow = meeting_time(gap, giver, ConstantSpeed(slow))
    alone = meeting_time(gap, giver, None)
    # A relative slack of 1e-12 absorbs rounding only; the models are monotone exactly.
    assert with_fast <= with_slow * (1 + 1e-12)
    assert with_slow <= alone * (1 + 1e-12)


@given(
    gap=gaps,
    extra=st.floats(min_value=1e-3, max_value=1000.0),
    profile=st.one_of(fatigue(), speeds.map(ConstantSpeed)),
)
def test_carrying_farther_takes_longer(gap: float, extra: float, profile: SpeedProfile) -> None:
    assert carrying_time(gap, profile) < carrying_time(gap + extra, profile)


@given(
    giver_at=st.tuples(coords, coords),
    receiver_at=st.tuples(coords, coords),
    giver=fatigue(),
    receiver=speeds.map(ConstantSpeed),
)
def test_each_robot_drives_its_own_share_to_the_meeting_point(
    giver_at: Point, receiver_at: Point, giver: Decelerating, receiver: ConstantSpeed
) -> None:
    gap = distance(giver_at, receiver_at)
    t = meeting_time(gap, giver, receiver)
    point = meeting_point(giver_at, receiver_at, giver, receiver)
    slack = 1e-9 * max(1.0, gap)
    assert distance(giver_at, point) == pytest.approx(giver.distance(t), abs=slack)
    assert distance(point, receiver_at) == pytest.approx(receiver.distance(t), abs=slack)


@given(
    gap=st.floats(min_value=0.1, max_value=50.0),
    sink_x=st.floats(min_value=1.0, max_value=100.0),
    angles=st.tuples(*[st.floats(min_value=-math.pi, max_value=math.pi)] * 2),
    giver=fatigue(),
    carrier=fatigue(),
    empty=speeds.map(ConstantSpeed),
)
def test_at_equal_gaps_the_partner_nearer_the_sink_wins(
    gap: float,
    sink_x: float,
    angles: tuple[float, float],
    giver: Decelerating,
    carrier: Decelerating,
    empty: ConstantSpeed,
) -> None:
    # Giver at the origin, sink on the +x axis, partners on the circle of radius `gap`.
    # Both meet at the same fraction f of the gap, and the meeting point's squared
    # distance to the sink, sink_x² - 2·sink_x·f·gap·cos θ + (f·gap)², falls as cos θ
    # rises, exactly as the partner's own distance to the sink does.
    near, far = sorted(angles, key=lambda angle: -math.cos(angle))

    def via(angle: float) -> float:
        partner_at = (gap * math.cos(angle), gap * math.sin(angle))
        return delivery_time((0.0, 0.0), giver, partner_at, empty, carrier, (sink_x, 0.0))

    assert via(near) <= via(far) * (1 + 1e-12)
