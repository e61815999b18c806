"""The Environment: exact poses of moving robots and vectorised range queries."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cas_async import (
    ConfigurationError,
    ConstantSpeed,
    Decelerating,
    PiecewiseSpeed,
    Pose,
    SimulationError,
    SpeedProfile,
    UnknownRobotError,
)
from cas_async.sim import Environment, Motion, Phase

PI = math.pi
FATIGUE = Decelerating(5.0, 1.0, 1.0)


@pytest.fixture
def env() -> Environment:
    world = Environment()
    world.add_robot(1, Pose(0, 0, 0))
    world.add_robot(2, Pose(3, 0, PI))
    world.add_robot(3, Pose(10, 10), mobile=False)
    return world


def test_membership(env: Environment) -> None:
    assert len(env) == 3
    assert 2 in env
    assert 7 not in env
    assert env.robot_ids == (1, 2, 3)
    assert env.is_mobile(1)
    assert not env.is_mobile(3)


def test_positions_at_follow_insertion_order_and_are_read_only(env: Environment) -> None:
    snapshot = env.positions_at(0.0)
    assert snapshot.ids.tolist() == [1, 2, 3]
    assert snapshot.xy.tolist() == [[0, 0], [3, 0], [10, 10]]
    assert snapshot.as_dict() == {1: (0.0, 0.0), 2: (3.0, 0.0), 3: (10.0, 10.0)}
    with pytest.raises(ValueError, match="read-only"):
        snapshot.xy[0, 0] = 5.0


def test_a_moving_robot_is_exact_at_every_instant(env: Environment) -> None:
    motion = Motion.straight_to(Pose(0, 0, 0), 0, 14, turn_rate=PI / 2, profile=FATIGUE)
    env.start_motion(1, motion, start_time=10.0)
    for t, y, heading in [
        (10.5, 0, PI / 4),
        (13.0, 8, PI / 2),
        (16.0, 13, PI / 2),
        (99, 14, PI / 2),
    ]:
        pose = env.pose_at(1, t)
        assert (pose.x, pose.y, pose.heading) == pytest.approx((0, y, heading), abs=1e-12)
        assert env.positions_at(t).xy[0].tolist() == pytest.approx([0, y], abs=1e-12)
    # Before the motion started, the robot is reported where it started from.
    assert env.positions_at(5.0).xy[0].tolist() == [0, 0]


def test_halt_stops_the_robot_where_it_is(env: Environment) -> None:
    env.start_motion(
        1, Motion.straight_to(Pose(0, 0), 10, 0, turn_rate=1, profile=ConstantSpeed(2)), 0
    )
    stopped = env.halt(1, 2.5)
    assert stopped == Pose(5, 0, 0)
    assert env.pose_at(1, 100) == stopped
    motion, since = env.motion_of(1)
    assert motion == Motion.standing(stopped)
    assert since == 2.5


def test_halting_after_the_end_is_exactly_the_end(env: Environment) -> None:
    motion = Motion.straight_to(Pose(0, 0), 0.1, 0.7, turn_rate=3, profile=FATIGUE)
    env.start_motion(1, motion, 1.0)
    assert env.halt(1, 1.0 + motion.duration) == motion.end


def test_remove_robot_keeps_the_others_in_order(env: Environment) -> None:
    env.start_motion(3 - 1, Motion.turn_to(Pose(3, 0, PI), 0, turn_rate=1), 0)
    env.remove_robot(1)
    assert env.robot_ids == (2, 3)
    assert env.positions_at(0).ids.tolist() == [2, 3]
    assert env.positions_at(0).xy.tolist() == [[3, 0], [10, 10]]
    env.add_robot(1, Pose(-1, -1))
    assert env.positions_at(0).ids.tolist() == [2, 3, 1]
    with pytest.raises(UnknownRobotError):
        env.remove_robot(99)


def test_within_is_nearest_first_inclusive_and_excludes_the_robot(env: Environment) -> None:
    env.add_robot(4, Pose(0, 3))
    env.add_robot(5, Pose(-2, 0))
    found = env.within(1, 3.0, 0.0)
    assert found.ids.tolist() == [5, 2, 4]  # 2 and 4 are both at 3: tie broken by id
    assert found.xy.tolist() == [[-2, 0], [3, 0], [0, 3]]
    assert env.within(1, 0.0, 0.0).ids.tolist() == []
    assert len(env.within(1, math.inf, 0.0)) == 4


def test_within_sees_robots_mid_move(env: Environment) -> None:
    env.start_motion(
        3 - 1,
        Motion.straight_to(Pose(3, 0, PI), 3, 100, turn_rate=math.inf, profile=ConstantSpeed(1)),
        0.0,
    )
    assert env.within(1, 5.0, 3.0).ids.tolist() == [2]  # at (3, 3): 4.24 away
    assert env.within(1, 5.0, 4.5).ids.tolist() == []  # at (3, 4.5): 5.41 away


def random_motion(rng: np.random.Generator, start: Pose) -> Motion:
    profile: SpeedProfile
    if rng.random() < 0.5:
        profile = ConstantSpeed(float(rng.uniform(0.5, 5)))
    else:
        v_min = float(rng.uniform(0.2, 2))
        profile = Decelerating(v_min + float(rng.uniform(0, 5)), float(rng.uniform(0, 2)), v_min)
    if rng.random() < 0.2:
        return Motion.turn_to(
            start, float(rng.uniform(-PI, PI)), turn_rate=float(rng.uniform(0.5, 3))
        )
    x, y = rng.uniform(0, 100, size=2)
    return Motion.straight_to(
        start, float(x), float(y), turn_rate=float(rng.uniform(0.5, 3)), profile=profile
    )


def test_within_matches_brute_force_on_a_large_swarm() -> None:
    rng = np.random.default_rng(20240518)
    env = Environment()
    motions: dict[int, tuple[Motion, float]] = {}
    for robot_id in range(3000):
        x, y = rng.uniform(0, 100, size=2)
        pose = Pose(float(x), float(y), float(rng.uniform(-PI, PI)))
        env.add_robot(robot_id * 7, pose, mobile=robot_id % 3 != 0)
        motions[robot_id * 7] = (Motion.standing(pose), -math.inf)
        if robot_id % 3 == 1:  # a third of the swarm is on the move
            motion, start = random_motion(rng, pose), float(rng.uniform(0, 20))
            env.start_motion(robot_id * 7, motion, start)
            motions[robot_id * 7] = (motion, start)
    t = 25.0
    reference = {rid: motion.pose_at(t - start) for rid, (motion, start) in motions.items()}
    snapshot = env.positions_at(t)
    expected_xy = np.array([[reference[r].x, reference[r].y] for r in snapshot.ids.tolist()])
    np.testing.assert_allclose(snapshot.xy, expected_xy, rtol=0, atol=1e-9)

    for robot_id in rng.choice(list(reference), size=25, replace=False).tolist():
        radius = float(rng.uniform(1, 15))
        here = reference[robot_id]
        distances = {
            other: math.hypot(p.x - here.x, p.y - here.y)
            for other, p in reference.items()
            if other != robot_id
        }
        found = env.within(robot_id, radius, t)
        got = set(found.ids.tolist())
        # Robots within a rounding error of the circle may fall either side.
        certain = {o for o, d in distances.items() if d <= radius - 1e-9}
        possible = {o for o, d in distances.items() if d <= radius + 1e-9}
        assert certain <= got <= possible
        ordered = [distances[o] for o in found.ids.tolist()]
        assert ordered == sorted(ordered)


profiles = st.one_of(
    st.builds(ConstantSpeed, st.floats(0.1, 10)),
    st.builds(lambda v, a: Decelerating(v + 0.5, a, 0.5), st.floats(0, 10), st.floats(0, 3)),
    st.builds(
        lambda a, d: PiecewiseSpeed((Phase(d, 0.0, a), Phase(math.inf, a * d + 0.1, 0.0))),
        st.floats(0.1, 3),
        st.floats(0.1, 4),
    ),
)
coordinates = st.floats(-100, 100)


@settings(max_examples=60)
@given(
    coordinates,
    coordinates,
    st.floats(-4, 4),
    coordinates,
    coordinates,
    profiles,
    st.floats(0, 100),
    st.floats(0, 1.2),
)
def test_vectorised_positions_agree_with_the_motion(
    x0: float,
    y0: float,
    h0: float,
    x1: float,
    y1: float,
    profile: SpeedProfile,
    start: float,
    fraction: float,
) -> None:
    env = Environment()
    env.add_robot(1, Pose(5, 5))
    env.add_robot(2, Pose(x0, y0, h0))
    motion = Motion.straight_to(Pose(x0, y0, h0), x1, y1, turn_rate=2.0, profile=profile)
    env.start_motion(2, motion, start)
    t = start + fraction * motion.duration
    expected = motion.pose_at(t - start)
    assert env.positions_at(t).xy[1].tolist() == pytest.approx([expected.x, expected.y], abs=1e-9)


def test_the_cache_is_cleared_by_a_new_motion(env: Environment) -> None:
    before = env.positions_at(1.0)
    assert env.positions_at(1.0) is before
    env.start_motion(
        1, Motion.straight_to(Pose(0, 0), 4, 0, turn_rate=1, profile=ConstantSpeed(4)), 0
    )
    assert env.positions_at(1.0).xy[0].tolist() == [4, 0]


def test_duplicate_robot_is_refused(env: Environment) -> None:
    with pytest.raises(ConfigurationError, match="robot 2 is already in the environment"):
        env.add_robot(2, Pose(0, 0))


@pytest.mark.parametrize(
    "call",
    [
        lambda e: e.pose_at(9, 0.0),
        lambda e: e.within(9, 1.0, 0.0),
        lambda e: e.start_motion(9, Motion.standing(Pose(0, 0)), 0.0),
        lambda e: e.halt(9, 0.0),
        lambda e: e.is_mobile(9),
        lambda e: e.motion_of(9),
    ],
    ids=["pose_at", "within", "start_motion", "halt", "is_mobile", "motion_of"],
)
def test_unknown_robot_is_named(env: Environment, call: object) -> None:
    with pytest.raises(UnknownRobotError, match="robot 9 is not in the environment"):
        call(env)  # type: ignore[operator]
    assert issubclass(UnknownRobotError, LookupError)


def test_immobile_robot_refuses_to_move_but_may_stand(env: Environment) -> None:
    here = Pose(10, 10)
    with pytest.raises(SimulationError, match="robot 3 is immobile"):
        env.start_motion(3, Motion.turn_to(here, 1.0, turn_rate=1), 0.0)
    env.start_motion(3, Motion.standing(here), 0.0)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda e: e.within(1, -1.0, 0.0), "radius must be >= 0"),
        (lambda e: e.within(1, math.nan, 0.0), "radius must be >= 0"),
        (lambda e: e.positions_at(math.nan), "t must be a number"),
        (lambda e: e.pose_at(1, math.nan), "t must be a number"),
        (lambda e: e.start_motion(1, Motion.standing(Pose(0, 0)), math.inf), "start_time"),
        (lambda e: e.start_motion(1, Motion.standing(Pose(1, 0)), 0.0), "robot 1 is at"),
    ],
    ids=["negative-radius", "nan-radius", "nan-t", "nan-t-pose", "inf-start", "teleport"],
)
def test_invalid_queries_and_motions(env: Environment, call: object, message: str) -> None:
    with pytest.raises(SimulationError, match=message):
        call(env)  # type: ignore[operator]


def test_time_does_not_go_backwards_for_a_robot(env: Environment) -> None:
    env.halt(1, 5.0)
    with pytest.raises(SimulationError, match="before its current one"):
        env.start_motion(1, Motion.standing(Pose(0, 0)), 4.0)
