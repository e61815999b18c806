"""Speed profiles: closed-form distance, its inverse, ageing, and closing times."""

from __future__ import annotations

import copy
import math
import pickle

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cas_async import ConstantSpeed, Decelerating, PiecewiseSpeed, SimulationError, SpeedProfile
from cas_async._body._phases import phase_starts
from cas_async._body._profiles import _merged
from cas_async.sim import Phase, check_phases, closing_time

INF = math.inf

# The thesis's scenario 1 (§5.8.1): speed 5, deceleration 1; the floor is ours.
FATIGUE = Decelerating(initial_speed=5.0, deceleration=1.0, min_speed=1.0)
# Starts from rest, accelerates at 1 for 2 s, then cruises at 2.
FROM_REST = PiecewiseSpeed((Phase(2.0, 0.0, 1.0), Phase(INF, 2.0, 0.0)))


@pytest.mark.parametrize(
    ("profile", "t", "speed", "distance"),
    [
        (ConstantSpeed(2.0), 0.0, 2.0, 0.0),
        (ConstantSpeed(2.0), 5.0, 2.0, 10.0),
        (FATIGUE, 1.0, 4.0, 4.5),
        (FATIGUE, 2.0, 3.0, 8.0),
        (FATIGUE, 4.0, 1.0, 12.0),  # reaches the floor at (5 - 1) / 1 = 4 s
        (FATIGUE, 6.0, 1.0, 14.0),  # minimum-velocity mode: 12 + 1 * 2
        (Decelerating(3.0, 1.0, 1.0), 2.0, 1.0, 4.0),  # already slowed: 3*2 - 2
        (Decelerating(3.0, 1.0, 1.0), 4.0, 1.0, 6.0),
        (Decelerating(2.0, 0.0, 1.0), 3.0, 2.0, 6.0),  # no deceleration: constant
        (Decelerating(1.0, 1.0, 1.0), 3.0, 1.0, 3.0),  # at the floor from the start
        (FROM_REST, 1.0, 1.0, 0.5),
        (FROM_REST, 3.0, 2.0, 4.0),
    ],
    ids=[
        "constant-start",
        "constant",
        "ramp-1s",
        "ramp-2s",
        "floor-reached",
        "floor-regime",
        "pre-slowed-ramp",
        "pre-slowed-floor",
        "no-deceleration",
        "already-at-floor",
        "from-rest-ramp",
        "from-rest-cruise",
    ],
)
def test_hand_computed_speed_and_distance(
    profile: SpeedProfile, t: float, speed: float, distance: float
) -> None:
    assert profile.speed_at(t) == pytest.approx(speed)
    assert profile.distance(t) == pytest.approx(distance)
    assert profile.time_for(distance) == pytest.approx(t)


@pytest.mark.parametrize(
    ("distance", "expected"),
    [(4.5, 1.0), (8.0, 2.0), (10.5, 3.0), (12.0, 4.0), (14.0, 6.0), (15.0, 7.0)],
)
def test_fatigue_time_for_is_exact_in_both_regimes(distance: float, expected: float) -> None:
    assert FATIGUE.time_for(distance) == pytest.approx(expected, rel=1e-15)


def test_floor_time_is_equation_5() -> None:
    assert FATIGUE.floor_time == 4.0
    assert Decelerating(2.0, 0.0, 1.0).floor_time == INF
    assert Decelerating(1.0, 3.0, 1.0).floor_time == 0.0


def test_from_rest_time_for_uses_the_quadratic_root() -> None:
    assert FROM_REST.time_for(1.0) == pytest.approx(math.sqrt(2.0))
    assert FROM_REST.time_for(0.0) == 0.0


def test_decelerating_ages_into_a_slower_decelerating_profile() -> None:
    assert FATIGUE.advanced(2.0) == Decelerating(3.0, 1.0, 1.0)
    assert FATIGUE.advanced(10.0) == Decelerating(1.0, 1.0, 1.0)
    assert FATIGUE.advanced(0.0) is FATIGUE
    assert ConstantSpeed(3.0).advanced(7.0) == ConstantSpeed(3.0)


def test_generic_ageing_cuts_the_current_phase() -> None:
    aged = FROM_REST.advanced(1.0)
    assert aged.phases() == (Phase(1.0, 1.0, 1.0), Phase(INF, 2.0, 0.0))
    assert FROM_REST.advanced(2.0).phases() == (Phase(INF, 2.0, 0.0),)
    assert FROM_REST.advanced(5.0).phases() == (Phase(INF, 2.0, 0.0),)


profiles = st.one_of(
    st.builds(ConstantSpeed, st.floats(0.1, 50)),
    st.builds(
        lambda v_min, extra, a: Decelerating(v_min + extra, a, v_min),
        st.floats(0.1, 5),
        st.floats(0, 20),
        st.floats(0, 5),
    ),
    st.builds(
        lambda v0, a, d, cruise: PiecewiseSpeed((Phase(d, v0, a), Phase(INF, cruise, 0.0))),
        st.floats(0, 10),
        st.floats(0.01, 3),
        st.floats(0.01, 5),
        st.floats(0.1, 10),
    ),
)


class Halving(SpeedProfile):
    """A user's own profile: it implements ``phases`` only."""

    def phases(self) -> tuple[Phase, ...]:
        return (Phase(1.0, 2.0, -1.0), Phase(INF, 1.0, 0.0))


@given(profiles)
def test_a_profile_works_out_its_phase_starts_once_and_stays_an_equal_value(
    profile: SpeedProfile,
) -> None:
    twin = copy.deepcopy(profile)  # a value that has not been asked yet
    starts = profile.starts()
    assert starts == tuple(phase_starts(profile.phases()))
    assert profile.starts() is starts  # kept: not worked out again
    assert profile == twin
    assert hash(profile) == hash(twin)
    assert repr(profile) == repr(twin)
    assert pickle.loads(pickle.dumps(profile)).starts() == starts


def test_a_users_profile_gets_its_phase_starts_from_its_phases() -> None:
    halving = Halving()
    assert halving.starts() == ((0.0, 0.0, Phase(1.0, 2.0, -1.0)), (1.0, 1.5, Phase(INF, 1.0, 0.0)))
    assert halving.distance(3.0) == 3.5
    assert halving.advanced(0.5).phases() == (Phase(0.5, 1.5, -1.0), Phase(INF, 1.0, 0.0))


@given(profiles, st.floats(0, 100))
def test_time_for_inverts_distance(profile: SpeedProfile, t: float) -> None:
    assert profile.time_for(profile.distance(t)) == pytest.approx(t, rel=1e-9, abs=1e-9)


@given(profiles, st.floats(0, 50), st.floats(0, 50))
def test_ageing_is_a_time_shift(profile: SpeedProfile, first: float, then: float) -> None:
    aged = profile.advanced(first)
    expected = profile.distance(first + then) - profile.distance(first)
    assert aged.distance(then) == pytest.approx(expected, rel=1e-9, abs=1e-9)
    assert aged.speed_at(then) == pytest.approx(profile.speed_at(first + then), abs=1e-9)


# A phase too short to move the clock: it starts at the very instant of the next one.
BLINK = PiecewiseSpeed((Phase(1e6, 1.0, 0.0), Phase(1e-12, 1.0, 0.5), Phase(INF, 1.0, 0.0)))


@given(st.one_of(profiles, st.just(BLINK), st.just(Halving())), st.floats(0, 2e6))
def test_one_profiles_closing_time_is_the_general_ones_figure_for_figure(
    profile: SpeedProfile, distance: float
) -> None:
    """A single profile takes a shortcut through its phases: it must not change a bit."""
    general = _merged(distance, [profile.starts()])
    assert closing_time(distance, (profile,)) == general
    assert profile.time_for(distance) == general


@given(
    st.one_of(profiles, st.just(BLINK)), st.one_of(profiles, st.just(Halving())), st.floats(0, 2e6)
)
def test_two_profiles_closing_time_is_the_general_ones_figure_for_figure(
    a: SpeedProfile, b: SpeedProfile, distance: float
) -> None:
    """Two robots meeting take a shortcut too: it must not change a bit either."""
    assert closing_time(distance, (a, b)) == _merged(distance, [a.starts(), b.starts()])
    assert closing_time(distance, (b, a)) == _merged(distance, [b.starts(), a.starts()])


@given(profiles, profiles, st.floats(0, 200))
def test_closing_time_covers_the_distance_together(
    a: SpeedProfile, b: SpeedProfile, distance: float
) -> None:
    t = closing_time(distance, (a, b))
    assert a.distance(t) + b.distance(t) == pytest.approx(distance, rel=1e-9, abs=1e-9)
    assert t <= min(a.time_for(distance), b.time_for(distance)) + 1e-9


@pytest.mark.parametrize(
    ("profiles", "distance", "expected"),
    [
        ((ConstantSpeed(5.0), FATIGUE), 9.5, 1.0),  # 10t - t^2/2 = 9.5 (equation 3)
        ((FATIGUE, FATIGUE), 30.0, 7.0),  # both reach the floor at 4 s (24), then 2/s
        ((FATIGUE, Decelerating(3.0, 1.0, 2.0)), 12.5, 2.0),  # floors at different times
        ((FATIGUE,), 14.0, 6.0),  # one robot: equation 4
    ],
    ids=["one-fresh-one-tired", "both-reach-floor", "mixed-breakpoints", "alone"],
)
def test_closing_time_hand_computed(
    profiles: tuple[SpeedProfile, ...], distance: float, expected: float
) -> None:
    assert closing_time(distance, profiles) == pytest.approx(expected)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: ConstantSpeed(0.0), "speed must be finite and > 0"),
        (lambda: ConstantSpeed(-1.0), "speed must be finite and > 0"),
        (lambda: ConstantSpeed(math.nan), "speed must be finite and > 0"),
        (lambda: Decelerating(2.0, 1.0, 3.0), "min_speed 3.0 exceeds initial_speed 2.0"),
        (lambda: Decelerating(5.0, -1.0, 1.0), "deceleration must be >= 0"),
        (lambda: Decelerating(5.0, 1.0, 0.0), "min_speed must be > 0"),
        (lambda: Decelerating(math.inf, 1.0, 1.0), "initial_speed must be finite"),
        (lambda: PiecewiseSpeed(()), "at least one phase"),
        (lambda: PiecewiseSpeed((Phase(1.0, 1.0, 0.0),)), "last phase must be a cruise"),
        (lambda: PiecewiseSpeed((Phase(INF, 0.0, 0.0),)), "last phase must be a cruise"),
        (lambda: PiecewiseSpeed((Phase(INF, 1.0, 0.0),) * 2), "finite duration > 0"),
        (lambda: PiecewiseSpeed((Phase(3.0, 1.0, -1.0), Phase(INF, 1.0, 0.0))), "below zero"),
        (lambda: PiecewiseSpeed((Phase(1.0, -1.0, 2.0), Phase(INF, 1.0, 0.0))), "speed must"),
        (lambda: FATIGUE.time_for(-1.0), "distance must be a finite number >= 0"),
        (lambda: FATIGUE.distance(math.nan), "t must be a finite number >= 0"),
        (lambda: FATIGUE.advanced(-1.0), "dt must be a finite number >= 0"),
        (lambda: closing_time(1.0, ()), "at least one speed profile"),
    ],
    ids=lambda value: value if isinstance(value, str) else "",
)
def test_invalid_profiles_are_refused_with_a_clear_message(make: object, message: str) -> None:
    with pytest.raises(SimulationError, match=message):
        make()  # type: ignore[operator]


def test_check_phases_returns_a_tuple() -> None:
    assert check_phases([Phase(INF, 1.0, 0.0)]) == (Phase(INF, 1.0, 0.0),)
