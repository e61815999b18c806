"""The diff-drive controller alone, on an exact unicycle: turn, drive, stop within tolerance."""

from __future__ import annotations

import math

import pytest

from cas_async import ConfigurationError, Pose
from cas_async.ros import DiffDriveController, DriveTuning
from cas_async.ros._fake_robot import _integrate

DT = 0.02  # 50 Hz odometry
STEPS = 5000  # 100 s of robot time at most per move


def drive(
    controller: DiffDriveController, pose: Pose, x: float, y: float, cruise: float = 0.5
) -> tuple[Pose, int, list[tuple[float, float]]]:
    """Runs the loop a RosDiffDrive runs: a command per odometry tick, until done."""
    controller.reset()
    commands = []
    for step in range(STEPS):
        velocity = controller.toward(pose, x, y, cruise)
        if velocity is None:
            return pose, step, commands
        commands.append(velocity)
        pose = _integrate(pose, *velocity, DT)
    raise AssertionError(f"did not reach ({x}, {y}) from {pose}")


@pytest.mark.parametrize(
    "goals",
    [
        [(2.0, 0.0), (2.0, 2.0), (0.0, 0.0)],
        [(-1.0, 0.5), (3.0, -2.0), (0.1, 0.1)],
        [(0.0, -4.0), (0.03, -4.0), (5.0, 5.0)],
    ],
    ids=["square", "zigzag", "tiny-step"],
)
def test_it_reaches_each_goal_within_tolerance_turning_first(
    goals: list[tuple[float, float]],
) -> None:
    controller = DiffDriveController()
    tolerance = controller.tuning.position_tolerance
    pose = Pose(0.0, 0.0, math.pi / 2)
    for x, y in goals:
        start = pose
        pose, steps, commands = drive(controller, pose, x, y)
        assert pose.distance_to(x, y) <= tolerance
        if start.distance_to(x, y) > tolerance:
            assert commands, "a move beyond the tolerance commands something"
            needs_turn = abs(math.remainder(start.bearing_to(x, y) - start.heading, math.tau))
            if needs_turn > controller.tuning.heading_tolerance:
                assert commands[0][0] == 0.0, "it turns in place first"
        else:
            assert steps == 0, "a goal within tolerance is reached at once"


def test_it_never_exceeds_its_limits_and_follows_the_cruise_speed() -> None:
    controller = DiffDriveController(DriveTuning(max_turn_rate=0.8))
    _, _, commands = drive(controller, Pose(0.0, 0.0), -3.0, 4.0, cruise=0.3)
    assert max(abs(turn) for _, turn in commands) <= 0.8
    assert max(speed for speed, _ in commands) == pytest.approx(0.3)
    assert min(speed for speed, _ in commands) >= 0.0, "it never backs up"


def test_it_turns_in_place_to_a_heading() -> None:
    controller = DiffDriveController()
    pose = Pose(1.0, 1.0, 0.0)
    for _ in range(STEPS):
        velocity = controller.facing(pose, -2.5)
        if velocity is None:
            break
        assert velocity[0] == 0.0
        assert velocity[1] < 0, "the short way round"
        pose = _integrate(pose, *velocity, DT)
    assert abs(math.remainder(pose.heading + 2.5, math.tau)) <= controller.tuning.heading_tolerance
    assert (pose.x, pose.y) == (1.0, 1.0)


def test_a_push_off_course_makes_it_turn_again() -> None:
    controller = DiffDriveController()
    pose = Pose(0.0, 0.0, 0.0)
    assert controller.toward(pose, 5.0, 0.0, 0.5) is not None
    assert not controller.turning
    assert controller.toward(Pose(1.0, 0.0, 1.2), 5.0, 0.0, 0.5) == (0.0, pytest.approx(-1.0))
    assert controller.turning


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("position_tolerance", 0.0),
        ("max_turn_rate", math.inf),
        ("turn_gain", -1.0),
        ("min_speed", math.nan),
    ],
)
def test_bad_tuning_is_refused_naming_the_field(field: str, value: float) -> None:
    with pytest.raises(ConfigurationError, match=f"DriveTuning.{field} must be"):
        DriveTuning(**{field: value})


def test_a_minimum_turn_rate_above_the_maximum_is_refused() -> None:
    with pytest.raises(ConfigurationError, match="min_turn_rate"):
        DriveTuning(min_turn_rate=2.0, max_turn_rate=1.0)
