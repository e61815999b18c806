"""The Floor: carries that keep the invariant, and every violation of it, caught and named.

Robots are placed and driven by hand in an Environment (no layers): each test
scripts the lifts, motions and put-downs of one situation.
"""

from __future__ import annotations

import math

import pytest

from apps.box_moving.floor import Floor
from apps.box_moving.messages import Side
from apps.box_moving.records import Box, FloorEventKind, FloorViolation
from cas_async.sim import Environment
from tests.box_moving.helpers import drive, floor_with

# Object 1 (weight 14, size 1) lies at (5, 5): its west side point is (4.5, 5),
# its east one (5.5, 5). Object 2 (weight 4, size 0.5) lies at (2, 2).
WEST_OF_1, EAST_OF_1, WEST_OF_2 = (4.5, 5.0), (5.5, 5.0), (1.75, 2.0)


def test_a_solo_carry_moves_the_object_with_its_lifter_and_counts_it_moved() -> None:
    environment, floor = floor_with({1: WEST_OF_2})
    floor.claim(1, 2, 0.0)
    floor.lift(1, 2, Side.WEST, None, 1.0)
    assert floor.lifters() == {1}
    end = drive(environment, 1, 8.75, 6.0, 1.0)  # the centre to the drop spot (9, 6)
    assert floor.position(2, (1.0 + end) / 2) == pytest.approx(((2 + 9) / 2, 4.0))
    floor.put_down(1, 2, end)
    assert floor.is_moved(2)
    assert floor.moved == 1
    assert floor.position(2, end + 5) == pytest.approx((9.0, 6.0))
    (delivery,) = floor.deliveries()
    assert (delivery.obj, delivery.t, delivery.selected, delivery.carriers) == (2, end, 0.0, (1,))
    assert delivery.distance == pytest.approx(math.hypot(7.0, 4.0))
    kinds = [event.kind for event in floor.events]
    assert kinds == [
        FloorEventKind.CLAIMED,
        FloorEventKind.LIFTED,
        FloorEventKind.CARRIED,
        FloorEventKind.PUT_DOWN,
        FloorEventKind.MOVED,
    ]
    floor.audit(end + 5)


def test_a_joint_carry_moves_the_object_between_its_two_lifters() -> None:
    environment, floor = floor_with({1: WEST_OF_1, 2: EAST_OF_1})
    floor.lift(1, 1, Side.WEST, 2, 0.0)
    floor.lift(2, 1, Side.EAST, 1, 0.5)
    end = drive(environment, 1, 7.5, 5.0, 1.0)
    assert drive(environment, 2, 8.5, 5.0, 1.0) == end
    floor.audit((1.0 + end) / 2)
    assert floor.position(1, (1.0 + end) / 2) == pytest.approx((6.5, 5.0))
    floor.put_down(1, 1, end)
    assert not floor.is_moved(1)  # robot 2 still holds its side
    floor.put_down(2, 1, end)
    assert floor.is_moved(1)
    assert floor.deliveries()[0].carriers == (1, 2)
    assert floor.deliveries()[0].joint


def test_a_robot_that_put_an_object_down_no_longer_moves_it() -> None:
    environment, floor = floor_with({1: WEST_OF_2})
    floor.lift(1, 2, Side.WEST, None, 0.0)
    end = drive(environment, 1, 2.75, 2.0, 0.0)
    floor.put_down(1, 2, end)  # outside the zone: it lies there, not moved
    away = drive(environment, 1, 0.0, 0.0, end)
    assert floor.position(2, away) == pytest.approx((3.0, 2.0))
    assert not floor.is_moved(2)
    assert [box.obj for box in floor.free(1)] == [1, 2]
    floor.audit(away)


def lift_heavy_alone(environment: Environment, floor: Floor) -> None:
    floor.lift(1, 1, Side.WEST, None, 0.0)


def lift_a_moved_object(environment: Environment, floor: Floor) -> None:
    floor.lift(3, 2, Side.WEST, None, 0.0)
    end = drive(environment, 3, 8.75, 6.0, 0.0)
    floor.put_down(3, 2, end)
    floor.lift(3, 2, Side.WEST, None, end)


def partners_that_disagree(environment: Environment, floor: Floor) -> None:
    floor.lift(1, 1, Side.WEST, 3, 0.0)
    floor.lift(2, 1, Side.EAST, 1, 0.0)


def a_pair_too_weak(environment: Environment, floor: Floor) -> None:
    floor.lift(2, 1, Side.EAST, 3, 0.0)  # payloads 6 + 6 for weight 14


def set_off_before_the_partner_lifts(environment: Environment, floor: Floor) -> None:
    floor.lift(1, 1, Side.WEST, 2, 0.0)
    drive(environment, 1, 2.0, 5.0, 3.0)


def set_off_when_the_partner_named_another(environment: Environment, floor: Floor) -> None:
    floor.lift(1, 1, Side.WEST, 2, 0.0)  # robot 2 never lifts: the pair is incomplete
    floor.lift(3, 2, Side.WEST, None, 0.0)
    drive(environment, 1, 4.5, 7.0, 1.0)


def drift_apart(environment: Environment, floor: Floor) -> None:
    floor.lift(1, 1, Side.WEST, 2, 0.0)
    floor.lift(2, 1, Side.EAST, 1, 0.0)
    end = drive(environment, 1, 3.5, 5.0, 1.0)  # robot 2 stays: a metre apart more
    environment.halt(1, end)


def drift_apart_found_by_the_audit(environment: Environment, floor: Floor) -> None:
    floor.lift(1, 1, Side.WEST, 2, 0.0)
    floor.lift(2, 1, Side.EAST, 1, 0.0)
    end = drive(environment, 1, 3.5, 5.0, 1.0)
    floor.audit(end)  # before anything halts: the audit at a sample


def put_down_what_it_does_not_hold(environment: Environment, floor: Floor) -> None:
    floor.lift(1, 1, Side.WEST, 2, 0.0)
    floor.put_down(2, 1, 1.0)


def lift_from_afar(environment: Environment, floor: Floor) -> None:
    floor.lift(3, 2, Side.EAST, None, 0.0)  # it stands at the west side


def lift_two_objects(environment: Environment, floor: Floor) -> None:
    floor.lift(3, 2, Side.WEST, None, 0.0)
    drive(environment, 3, *WEST_OF_1, 0.0)
    floor.lift(3, 1, Side.WEST, 1, 20.0)


def a_third_lifter(environment: Environment, floor: Floor) -> None:
    floor.lift(1, 1, Side.WEST, 2, 0.0)
    floor.lift(2, 1, Side.EAST, 1, 0.0)
    end = drive(environment, 3, 5.0, 5.5, 0.0)
    floor.lift(3, 1, Side.NORTH, 1, end)


def the_last_lifter_walks_off_with_it(environment: Environment, floor: Floor) -> None:
    floor.lift(1, 1, Side.WEST, 2, 0.0)
    floor.lift(2, 1, Side.EAST, 1, 0.0)
    floor.put_down(1, 1, 1.0)
    drive(environment, 2, 7.0, 5.0, 2.0)


VIOLATIONS = [
    (lift_heavy_alone, 1, "beyond its payload"),
    (lift_a_moved_object, 3, "stays put"),
    (partners_that_disagree, 2, "does not agree"),
    (a_pair_too_weak, 2, "cannot lift"),
    (set_off_before_the_partner_lifts, 1, "the pair is incomplete"),
    (set_off_when_the_partner_named_another, 1, "does not lift it"),
    (drift_apart, 1, "two places"),
    (drift_apart_found_by_the_audit, 1, "two places"),
    (put_down_what_it_does_not_hold, 2, "does not lift"),
    (lift_from_afar, 3, "side point"),
    (lift_two_objects, 3, "second object"),
    (a_third_lifter, 3, "two robots"),
    (the_last_lifter_walks_off_with_it, 2, "the pair is incomplete"),
]


@pytest.mark.parametrize(
    ("script", "robot", "problem"), VIOLATIONS, ids=[script.__name__ for script, *_ in VIOLATIONS]
)
def test_every_violation_is_caught_naming_robot_object_and_instant(
    script: object, robot: int, problem: str
) -> None:
    environment, floor = floor_with({1: WEST_OF_1, 2: EAST_OF_1, 3: WEST_OF_2})
    with pytest.raises(FloorViolation, match=problem) as caught:
        script(environment, floor)  # type: ignore[operator]
    violation = caught.value
    assert violation.robot == robot
    assert f"robot {robot}, object {violation.obj}" in str(violation)
    assert str(violation).startswith(f"t={violation.t:.6g}")


def test_a_refused_lift_changes_nothing() -> None:
    environment, floor = floor_with({1: WEST_OF_1})
    with pytest.raises(FloorViolation):
        floor.lift(1, 1, Side.WEST, None, 0.0)
    assert floor.lifters() == set()
    assert floor.events == ()
    drive(environment, 1, 0.0, 0.0, 0.0)  # free to go: it holds nothing
    floor.audit(3.0)


def test_a_floor_refuses_two_objects_with_one_id() -> None:
    with pytest.raises(ValueError, match="share an id"):
        floor_with({1: WEST_OF_1}, boxes=[Box(1, 0, 0, 1, 1, 9, 5), Box(1, 2, 2, 1, 1, 9, 6)])


def test_claims_hide_an_object_from_the_others_scans_until_released() -> None:
    _, floor = floor_with({1: WEST_OF_1, 2: EAST_OF_1})
    floor.claim(1, 2, 0.0)
    assert [box.obj for box in floor.free(2)] == [1]
    assert [box.obj for box in floor.free(1)] == [1, 2]
    floor.unclaim(2, 2, 1.0)  # not its mark: nothing happens
    assert [box.obj for box in floor.free(2)] == [1]
    floor.unclaim(1, 2, 2.0)
    assert [box.obj for box in floor.free(2)] == [1, 2]
