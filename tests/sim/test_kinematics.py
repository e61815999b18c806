"""Motions: rotate in place, then drive straight; exact poses at every instant."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cas_async import ConstantSpeed, Decelerating, Pose, SimulationError
from cas_async.sim import Motion

PI = math.pi
FATIGUE = Decelerating(5.0, 1.0, 1.0)


def approx_pose(pose: Pose, x: float, y: float, heading: float) -> None:
    assert (pose.x, pose.y) == pytest.approx((x, y), abs=1e-12)
    assert pose.heading == pytest.approx(heading, abs=1e-12)


@pytest.fixture
def north() -> Motion:
    """From the origin facing +x to (0, 14): a quarter turn in 1 s, then 6 s of fatigue."""
    return Motion.straight_to(Pose(0, 0, 0), 0, 14, turn_rate=PI / 2, profile=FATIGUE)


def test_durations_are_closed_form(north: Motion) -> None:
    assert north.turn == pytest.approx(PI / 2)
    assert north.rotation_time == pytest.approx(1.0)
    assert north.length == 14.0
    assert north.translation_time == pytest.approx(6.0)  # 12 in 4 s, then 2 at the floor
    assert north.duration == pytest.approx(7.0)


@pytest.mark.parametrize(
    ("elapsed", "x", "y", "heading"),
    [
        (-1.0, 0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0, 0.0),
        (0.5, 0.0, 0.0, PI / 4),  # half-way through the rotation
        (1.0, 0.0, 0.0, PI / 2),  # rotation over, translation starting
        (3.0, 0.0, 8.0, PI / 2),  # 2 s of translation: 5*2 - 2^2/2
        (5.0, 0.0, 12.0, PI / 2),  # floor reached
        (6.0, 0.0, 13.0, PI / 2),  # minimum speed
        (7.0, 0.0, 14.0, PI / 2),
        (100.0, 0.0, 14.0, PI / 2),
    ],
    ids=[
        "before",
        "start",
        "mid-rotation",
        "rotated",
        "ramp",
        "at-floor",
        "floor",
        "end",
        "after",
    ],
)
def test_pose_at_every_phase(
    north: Motion, elapsed: float, x: float, y: float, heading: float
) -> None:
    approx_pose(north.pose_at(elapsed), x, y, heading)


def test_the_end_pose_is_exactly_the_target() -> None:
    motion = Motion.straight_to(Pose(0.1, 0.2), 0.7, -1.3, turn_rate=1.0, profile=FATIGUE)
    assert (motion.end.x, motion.end.y) == (0.7, -1.3)
    assert motion.pose_at(motion.duration) == motion.end


def test_translating_time_and_travelled(north: Motion) -> None:
    assert north.translating_time(0.5) == 0.0
    assert north.translating_time(3.0) == pytest.approx(2.0)
    assert north.translating_time(50.0) == pytest.approx(6.0)
    assert north.travelled(3.0) == pytest.approx(8.0)
    assert north.travelled(50.0) == 14.0


def test_already_facing_the_target_means_no_rotation() -> None:
    motion = Motion.straight_to(Pose(0, 0, PI / 2), 0, 4, turn_rate=1.0, profile=ConstantSpeed(2))
    assert motion.rotation_time == 0.0
    assert motion.duration == 2.0
    approx_pose(motion.pose_at(1.0), 0, 2, PI / 2)


def test_zero_length_move_keeps_pose_and_takes_no_time() -> None:
    start = Pose(3, 4, 1.0)
    motion = Motion.straight_to(start, 3, 4, turn_rate=1.0, profile=ConstantSpeed(1))
    assert motion == Motion.standing(start)
    assert motion.duration == 0.0
    assert motion.pose_at(5.0) == start


def test_rotation_to_the_current_heading_takes_no_time() -> None:
    motion = Motion.turn_to(Pose(1, 1, 0.5), 0.5 + 2 * PI, turn_rate=1.0)
    assert motion.duration == 0.0
    assert motion.end == Pose(1, 1, 0.5)


@pytest.mark.parametrize(
    ("start", "target", "turn"),
    [
        (0.0, PI / 2, PI / 2),
        (0.0, -PI / 2, -PI / 2),
        (0.0, PI, PI),  # a half turn goes counter-clockwise
        (PI / 2, -PI / 2, PI),
        (3.0, -3.0, 2 * PI - 6.0),  # the short way crosses the +-pi seam
    ],
    ids=["left", "right", "half-turn", "half-turn-from-north", "across-seam"],
)
def test_rotations_take_the_short_way(start: float, target: float, turn: float) -> None:
    motion = Motion.turn_to(Pose(0, 0, start), target, turn_rate=2.0)
    assert motion.turn == pytest.approx(turn)
    assert motion.rotation_time == pytest.approx(abs(turn) / 2.0)
    middle = motion.pose_at(motion.rotation_time / 2)
    assert middle.heading == pytest.approx(Pose(0, 0, start + turn / 2).heading)
    assert motion.end.heading == Pose(0, 0, target).heading


def test_infinite_turn_rate_turns_instantly() -> None:
    motion = Motion.straight_to(Pose(0, 0), -3, 0, turn_rate=math.inf, profile=ConstantSpeed(3))
    assert motion.rotation_time == 0.0
    assert motion.duration == 1.0
    approx_pose(motion.pose_at(0.5), -1.5, 0, PI)


coordinates = st.floats(-1e3, 1e3)


@given(coordinates, coordinates, st.floats(-4, 4), coordinates, coordinates, st.floats(0, 1))
def test_translation_stays_on_the_segment_and_progresses(
    x0: float, y0: float, h0: float, x1: float, y1: float, fraction: float
) -> None:
    motion = Motion.straight_to(Pose(x0, y0, h0), x1, y1, turn_rate=1.5, profile=FATIGUE)
    pose = motion.pose_at(fraction * motion.duration)
    done = Pose(x0, y0).distance_to(pose.x, pose.y)
    left = Pose(x1, y1).distance_to(pose.x, pose.y)
    assert done + left == pytest.approx(motion.length, abs=1e-6)
    assert done == pytest.approx(motion.travelled(fraction * motion.duration), abs=1e-6)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: Motion.straight_to(Pose(0, 0), math.nan, 1, turn_rate=1, profile=FATIGUE), "x"),
        (lambda: Motion.straight_to(Pose(0, 0), 1, math.inf, turn_rate=1, profile=FATIGUE), "y"),
        (lambda: Motion.straight_to(Pose(0, 0), 1, 1, turn_rate=0, profile=FATIGUE), "turn_rate"),
        (lambda: Motion.turn_to(Pose(0, 0), 1.0, turn_rate=-1), "turn_rate"),
        (lambda: Motion.turn_to(Pose(0, 0), 1.0, turn_rate=math.nan), "turn_rate"),
        (lambda: Motion.turn_to(Pose(0, 0), math.nan, turn_rate=1), "heading"),
        (lambda: Motion.standing(Pose(0, 0)).pose_at(math.nan), "elapsed"),
    ],
    ids=[
        "nan-x",
        "inf-y",
        "zero-turn-rate",
        "negative-turn-rate",
        "nan-turn-rate",
        "nan-heading",
        "nan-elapsed",
    ],
)
def test_invalid_motions_are_refused_naming_the_value(make: object, message: str) -> None:
    with pytest.raises(SimulationError, match=message):
        make()  # type: ignore[operator]
