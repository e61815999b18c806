"""The Environment's items and odometers: hand-overs within reach, no robot leaves holding one."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest

from cas_async import ConstantSpeed, Decelerating, Pose, SimulationError, UnknownRobotError
from cas_async.sim import Environment, ItemEvent, ItemEventKind, Motion

PI = math.pi


@pytest.fixture
def env() -> Environment:
    """Robot 1 at the origin, robot 2 three metres east, robot 3 far away and immobile."""
    world = Environment()
    world.add_robot(1, Pose(0, 0, 0))
    world.add_robot(2, Pose(3, 0, PI))
    world.add_robot(3, Pose(10, 10), mobile=False)
    world.items.subscribe(lambda _: world.items.check())
    return world


def drive(env: Environment, robot: int, x: float, y: float, t: float, speed: float = 1.0) -> Motion:
    """Starts a straight move of ``robot`` at ``t`` from where it is, turning instantly."""
    motion = Motion.straight_to(
        env.pose_at(robot, t), x, y, turn_rate=math.inf, profile=ConstantSpeed(speed)
    )
    env.start_motion(robot, motion, t)
    return motion


# -- items ----------------------------------------------------------------------------------


def test_items_are_created_handed_over_and_retired_through_the_ledger(env: Environment) -> None:
    item = env.create_item(1, 0.0)
    assert env.items.held_by(1) == (item,)
    env.hand_over(item, 1, 2, 1.0, reach=3.0)  # exactly at reach: inclusive
    assert env.items.holder(item) == 2
    env.retire_item(item, 2, 2.0)
    assert env.items.holder(item) is None
    assert env.items.history(item) == (
        ItemEvent(0.0, ItemEventKind.CREATED, item, 1),
        ItemEvent(1.0, ItemEventKind.TRANSFERRED, item, 1, 2),
        ItemEvent(2.0, ItemEventKind.RETIRED, item, 2),
    )


def test_a_hand_over_beyond_reach_names_both_positions_and_changes_nothing(
    env: Environment,
) -> None:
    item = env.create_item(1, 0.0)
    with pytest.raises(
        SimulationError,
        match=r"robot 1 at \(0.0, 0.0\) cannot hand item 1 to robot 2 at \(3.0, 0.0\) at 1.0: "
        r"they are 3.0 apart, beyond the reach of 2.5",
    ):
        env.hand_over(item, 1, 2, 1.0, reach=2.5)
    assert env.items.holder(item) == 1
    assert env.items.transfers == 0


def test_a_hand_over_meets_a_moving_robot_at_its_exact_position(env: Environment) -> None:
    item = env.create_item(2, 0.0)
    # Robot 1 drives east at 1 m/s from t=10 (turning instantly); robot 2 stands at x=3.
    drive(env, 1, 6, 0, t=10.0)
    with pytest.raises(SimulationError, match=r"they are 0\.5 apart"):
        env.hand_over(item, 2, 1, 12.5, reach=1e-6)
    env.hand_over(item, 2, 1, 13.0, reach=1e-6)  # at (3, 0) exactly then
    assert env.items.holder(item) == 1
    # And back while it is still moving, within a reach of 1 m.
    env.hand_over(item, 1, 2, 13.75, reach=1.0)
    with pytest.raises(SimulationError, match=r"at \(4\.5, 0\.0\)"):
        env.hand_over(item, 2, 1, 14.5, reach=1.0)
    assert env.items.holder(item) == 2


def test_an_immobile_robot_can_give_and_receive(env: Environment) -> None:
    item = env.create_item(3, 0.0)
    drive(env, 1, 10, 10, t=0.0)
    env.hand_over(item, 3, 1, 20.0, reach=0.0)  # robot 1 arrived at (10, 10) long before
    assert env.items.held_by(1) == (item,)


def test_remove_robot_refuses_while_it_holds_items(env: Environment) -> None:
    first, second = env.create_item(2, 0.0), env.create_item(2, 0.0)
    with pytest.raises(SimulationError, match=r"robot 2 holds items \[1, 2\]: hand them over"):
        env.remove_robot(2)
    assert 2 in env
    env.hand_over(first, 2, 1, 1.0, reach=5.0)
    env.retire_item(second, 2, 1.0)
    env.remove_robot(2)
    assert env.robot_ids == (1, 3)
    env.items.check()


ITEM_CALLS: list[tuple[Callable[[Environment], object], type[Exception], str]] = [
    (lambda e: e.create_item(9, 0.0), UnknownRobotError, "robot 9 is not in the environment"),
    (
        lambda e: e.hand_over(1, 9, 2, 1.0, reach=1e9),
        UnknownRobotError,
        "robot 9 is not in the environment",
    ),
    (
        lambda e: e.hand_over(1, 1, 9, 1.0, reach=1e9),
        UnknownRobotError,
        "robot 9 is not in the environment",
    ),
    (lambda e: e.retire_item(1, 9, 1.0), UnknownRobotError, "robot 9 is not in the environment"),
    (lambda e: e.create_item(1, math.inf), SimulationError, "t must be a finite number"),
    (lambda e: e.hand_over(1, 1, 2, 1.0, reach=-1.0), SimulationError, "reach must be >= 0"),
    (lambda e: e.hand_over(1, 1, 2, 1.0, reach=math.nan), SimulationError, "reach must be >= 0"),
    (lambda e: e.hand_over(1, 1, 2, math.nan, reach=9.0), SimulationError, "t must be a finite"),
    (lambda e: e.hand_over(1, 1, 2, math.inf, reach=9.0), SimulationError, "t must be a finite"),
    (lambda e: e.hand_over(1, 1, 2, -math.inf, reach=9.0), SimulationError, "t must be a finite"),
    (lambda e: e.hand_over(1, 2, 1, 1.0, reach=9.0), SimulationError, "robot 2 does not hold it"),
    (lambda e: e.hand_over(1, 1, 1, 1.0, reach=9.0), SimulationError, "hand an item to itself"),
    (lambda e: e.hand_over(5, 1, 2, 1.0, reach=9.0), SimulationError, "item 5 is unknown"),
    (lambda e: e.retire_item(1, 2, 1.0), SimulationError, "robot 2 does not hold it"),
]


@pytest.mark.parametrize(
    ("call", "error", "message"),
    ITEM_CALLS,
    ids=[
        "create-unknown-robot",
        "give-unknown-giver",
        "give-unknown-receiver",
        "retire-unknown-robot",
        "create-inf-time",
        "negative-reach",
        "nan-reach",
        "nan-time",
        "inf-time",
        "minus-inf-time",
        "not-the-holder",
        "to-itself",
        "unknown-item",
        "retire-not-held",
    ],
)
def test_invalid_item_calls_are_refused_and_change_nothing(
    env: Environment, call: Callable[[Environment], object], error: type[Exception], message: str
) -> None:
    env.create_item(1, 0.0)
    with pytest.raises(error, match=message):
        call(env)
    assert env.items.holder(1) == 1
    assert (env.items.created, env.items.transfers, env.items.retired) == (1, 0, 0)


# -- odometer -------------------------------------------------------------------------------


def test_a_robot_that_never_moved_travelled_nothing(env: Environment) -> None:
    assert env.distance_travelled(1, 100.0) == 0.0
    assert env.distance_travelled(1, -math.inf) == 0.0
    assert env.distances(5.0) == {1: 0.0, 2: 0.0, 3: 0.0}


def test_the_odometer_adds_up_moves_and_is_exact_mid_move(env: Environment) -> None:
    drive(env, 1, 4, 0, t=0.0, speed=2.0)  # 4 m in 2 s
    assert env.distance_travelled(1, 1.0) == 2.0
    env.halt(1, 2.0)  # arrived: the standing motion replaces the finished move
    drive(env, 1, 4, 3, t=5.0)  # 3 m north at 1 m/s
    assert env.distance_travelled(1, 6.5) == 5.5
    drive(env, 1, 0, 0, t=8.0, speed=5.0)  # 5 m back in 1 s
    assert env.distance_travelled(1, 8.5) == pytest.approx(9.5)
    assert env.distance_travelled(1, 100.0) == pytest.approx(12.0)
    assert env.distances(100.0) == pytest.approx({1: 12.0, 2: 0.0, 3: 0.0})


def test_a_halted_move_counts_only_what_was_driven(env: Environment) -> None:
    # Rotate a quarter turn in 1 s (rotations add nothing), then 6 m under fatigue.
    motion = Motion.straight_to(
        Pose(0, 0, 0), 0, 14, turn_rate=PI / 2, profile=Decelerating(5, 1, 1)
    )
    env.start_motion(1, motion, 0.0)
    assert env.distance_travelled(1, 1.0) == 0.0
    stopped = env.halt(1, 3.0)  # cancelled after 2 s of translation: 5*2 - 2 = 8 m
    assert stopped.y == pytest.approx(8.0)
    assert env.distance_travelled(1, 3.0) == pytest.approx(8.0)
    assert env.distance_travelled(1, 50.0) == pytest.approx(8.0)
    drive(env, 1, 0, 0, t=10.0)
    assert env.distance_travelled(1, 12.0) == pytest.approx(10.0)
    assert env.distance_travelled(1, 99.0) == pytest.approx(16.0)


def test_a_motion_replaced_mid_way_keeps_what_it_drove(env: Environment) -> None:
    drive(env, 2, 3, 10, t=0.0)  # north at 1 m/s
    drive(env, 2, 0, 4, t=4.0)  # re-planned from (3, 4) without halting: 3 m west
    assert env.distance_travelled(2, 4.0) == 4.0
    assert env.distance_travelled(2, 20.0) == 7.0
    assert env.distances(20.0)[2] == 7.0


def test_before_the_current_motion_the_odometer_reads_its_start(env: Environment) -> None:
    drive(env, 1, 2, 0, t=0.0)
    drive(env, 1, 2, 2, t=2.0)
    assert env.distance_travelled(1, 1.0) == 2.0  # only the current motion is kept


def test_odometer_queries_are_checked(env: Environment) -> None:
    with pytest.raises(UnknownRobotError, match="robot 9 is not in the environment"):
        env.distance_travelled(9, 0.0)
    with pytest.raises(SimulationError, match="t must be a number"):
        env.distance_travelled(1, math.nan)
    with pytest.raises(SimulationError, match="t must be a number"):
        env.distances(math.nan)
