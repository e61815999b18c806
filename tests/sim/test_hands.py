"""Held-out hands: ``accept_from`` / ``refuse_from`` decide whom a robot takes items from.

A robot takes items from anyone until it first names a giver (``accept_from``) or
withdraws its hands (``refuse_from``); from then on it takes them only from the
givers it accepted and has not refused since. A refused hand-over is a
``SimulationError`` that changes nothing.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from cas_async import (
    ConstantSpeed,
    Hands,
    Middleware,
    Pose,
    Positions,
    SimulationError,
    SpeedProfile,
    UnknownRobotError,
    VirtualClock,
)
from cas_async.sim import Environment, SimulatedHands
from tests.sim.conftest import Sim

REACH = 1.0


@pytest.fixture
def env() -> Environment:
    """Robots 1 to 4 side by side, well within REACH of each other; the ledger audited."""
    world = Environment()
    for robot_id in (1, 2, 3, 4):
        world.add_robot(robot_id, Pose(0.1 * robot_id, 0.0))
    world.items.subscribe(lambda _: world.items.check())
    return world


def give(env: Environment, giver: int, receiver: int, t: float = 1.0) -> int:
    """Creates an item in ``giver``'s hands and hands it to ``receiver`` at ``t``."""
    item = env.create_item(giver, 0.0)
    env.hand_over(item, giver, receiver, t, reach=REACH)
    return item


def refused(env: Environment, giver: int, receiver: int, t: float = 1.0) -> str:
    """Hands a new item from ``giver`` to ``receiver``, expecting a refusal that changes nothing.

    Returns the error message.
    """
    item = env.create_item(giver, 0.0)
    transfers, history = env.items.transfers, env.items.history(item)
    with pytest.raises(SimulationError) as caught:
        env.hand_over(item, giver, receiver, t, reach=REACH)
    assert env.items.holder(item) == giver
    assert env.items.transfers == transfers
    assert env.items.history(item) == history
    assert item not in env.items.held_by(receiver)
    env.items.check()
    return str(caught.value)


# -- the Environment ----------------------------------------------------------------------


def test_a_robot_that_never_chose_takes_items_from_anyone(env: Environment) -> None:
    for giver in (1, 3, 4):
        item = give(env, giver, 2)
        assert env.items.holder(item) == 2
    assert len(env.items.held_by(2)) == 3


def test_after_accept_from_a_robot_takes_items_only_from_that_giver(env: Environment) -> None:
    env.accept_from(2, 1)
    for stranger in (3, 4):
        refused(env, stranger, 2)
    item = give(env, 1, 2)
    assert env.items.holder(item) == 2


def test_a_refusal_names_both_robots_the_instant_and_whom_it_takes_from(
    env: Environment,
) -> None:
    env.accept_from(2, 4)
    env.accept_from(2, 1)
    message = refused(env, 3, 2, t=2.5)
    assert message == "robot 2 does not take items from robot 3 at 2.5 (it takes them from [1, 4])"


def test_a_sink_accepts_several_givers_at_once(env: Environment) -> None:
    sink = 4
    env.accept_from(sink, 1)
    env.accept_from(sink, 2)
    first, second = give(env, 1, sink), give(env, 2, sink)
    assert env.items.held_by(sink) == (first, second)
    refused(env, 3, sink)


def test_accepting_the_same_giver_twice_is_the_same_as_once(env: Environment) -> None:
    env.accept_from(2, 1)
    env.accept_from(2, 1)
    env.refuse_from(2, 1)  # one refusal withdraws it: no count of acceptances
    refused(env, 1, 2)


def test_refuse_from_withdraws_one_giver_and_keeps_the_others(env: Environment) -> None:
    env.accept_from(4, 1)
    env.accept_from(4, 2)
    env.refuse_from(4, 1)
    refused(env, 1, 4)
    assert env.items.holder(give(env, 2, 4)) == 4


def test_refuse_from_on_a_robot_that_never_accepted_makes_it_refuse_everyone(
    env: Environment,
) -> None:
    env.refuse_from(2, 1)
    for giver in (1, 3, 4):
        assert refused(env, giver, 2).endswith("(it takes them from [])")


def test_refusing_a_giver_never_accepted_keeps_the_accepted_ones(env: Environment) -> None:
    env.accept_from(2, 1)
    env.refuse_from(2, 3)
    assert env.items.holder(give(env, 1, 2)) == 2
    refused(env, 3, 2)


def test_hands_can_be_held_out_again_after_withdrawing_them(env: Environment) -> None:
    env.accept_from(2, 1)
    env.refuse_from(2, 1)
    refused(env, 1, 2)
    env.accept_from(2, 1)
    assert env.items.holder(give(env, 1, 2, t=2.0)) == 2


def test_whom_a_robot_takes_from_is_its_own_choice(env: Environment) -> None:
    env.accept_from(2, 1)
    # Robot 3 never chose: it still takes from anyone, robot 2 included.
    assert env.items.holder(give(env, 4, 3)) == 3
    # And robot 2 gives to anyone: accepting restricts taking, not giving.
    item = give(env, 1, 2)
    env.hand_over(item, 2, 3, 2.0, reach=REACH)
    assert env.items.holder(item) == 3


def test_the_reach_is_checked_before_the_hands(env: Environment) -> None:
    env.add_robot(5, Pose(50.0, 0.0))
    env.accept_from(5, 1)
    item = env.create_item(3, 0.0)
    with pytest.raises(SimulationError, match="beyond the reach"):
        env.hand_over(item, 3, 5, 1.0, reach=REACH)


def test_a_refused_hand_over_leaves_the_item_free_to_go_elsewhere(env: Environment) -> None:
    env.accept_from(2, 1)
    item = env.create_item(3, 0.0)
    with pytest.raises(SimulationError, match="does not take items"):
        env.hand_over(item, 3, 2, 1.0, reach=REACH)
    env.hand_over(item, 3, 4, 1.0, reach=REACH)  # same instant, another receiver
    assert env.items.holder(item) == 4
    assert env.items.transfers == 1


UNKNOWN: list[tuple[Callable[[Environment], None], str]] = [
    (lambda e: e.accept_from(9, 1), "robot 9 is not in the environment"),
    (lambda e: e.accept_from(1, 9), "robot 9 is not in the environment"),
    (lambda e: e.refuse_from(9, 1), "robot 9 is not in the environment"),
]


@pytest.mark.parametrize(
    ("call", "message"),
    UNKNOWN,
    ids=["accept-unknown-receiver", "accept-unknown-giver", "refuse-unknown-receiver"],
)
def test_unknown_robots_are_refused_and_change_nothing(
    env: Environment, call: Callable[[Environment], None], message: str
) -> None:
    with pytest.raises(UnknownRobotError, match=message):
        call(env)
    # Robot 1 still takes from anyone: the failed call did not close its hands.
    assert env.items.holder(give(env, 2, 1)) == 1
    assert env.items.holder(give(env, 3, 1)) == 1


def test_a_removed_robot_is_unknown_to_accept_from(env: Environment) -> None:
    env.remove_robot(3)
    with pytest.raises(UnknownRobotError, match="robot 3 is not in the environment"):
        env.accept_from(2, 3)
    with pytest.raises(UnknownRobotError, match="robot 3 is not in the environment"):
        env.refuse_from(3, 2)


# -- the simulated hands -----------------------------------------------------------------


def hands(env: Environment, robot_id: int, clock: VirtualClock) -> SimulatedHands:
    return SimulatedHands(env, robot_id, clock, reach=REACH)


@pytest.mark.cas_virtual
async def test_the_simulated_hands_hold_out_and_withdraw(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> list[object]:
        env.items.subscribe(lambda _: env.items.check())
        env.add_robot(2, Pose(0.5, 0))
        env.add_robot(3, Pose(0, 0.5))
        giver, keeper, stranger = (hands(env, r, clock) for r in (1, 2, 3))
        log: list[object] = []
        await keeper.accept_from(1)
        item = await stranger.create_item()
        with pytest.raises(SimulationError, match="robot 2 does not take items from robot 3"):
            await stranger.hand_over(item, 2)
        log.append(await stranger.items())
        mine = await giver.create_item()
        await giver.hand_over(mine, 2)
        log.append(await keeper.items())
        await keeper.refuse_from(1)
        again = await giver.create_item()
        with pytest.raises(SimulationError, match=r"it takes them from \[\]"):
            await giver.hand_over(again, 2)
        log += [await giver.items(), await keeper.items()]
        return log

    assert await main(*sim) == [(1,), (2,), (3,), (2,)]


@pytest.mark.cas_virtual
async def test_the_simulated_hands_refuse_unknown_givers(sim: Sim) -> None:
    async def main(env: Environment, clock: VirtualClock) -> None:
        robot = hands(env, 1, clock)
        with pytest.raises(UnknownRobotError, match="robot 9 is not in the environment"):
            await robot.accept_from(9)

    await main(*sim)


class Hardware(Middleware):
    """A hardware robot's middleware: motion and perception only, no hands, no simulator."""

    @property
    def robot_id(self) -> int:
        return 1

    @property
    def speed_profile(self) -> SpeedProfile:
        return ConstantSpeed(1)

    @speed_profile.setter
    def speed_profile(self, profile: SpeedProfile) -> None:
        pass

    def pose(self) -> Pose:
        return Pose(0, 0)

    async def move_to(self, x: float, y: float) -> Pose:
        return Pose(x, y)

    async def rotate_to(self, heading: float) -> Pose:
        return Pose(0, 0, heading)

    async def robots_within(self, radius: float) -> Positions:
        raise NotImplementedError


def test_a_middleware_needs_no_hands() -> None:
    robot = Hardware()
    assert not hasattr(robot, "hand_over")
    assert isinstance(robot, Middleware)
    assert not isinstance(robot, Hands)


def test_the_middleware_interface_does_not_need_the_simulator() -> None:
    import subprocess
    import sys

    code = (
        "import sys, cas_async; "
        "from cas_async import Middleware, Hands, Pose, Positions, ConstantSpeed; "
        "print(sorted(m for m in sys.modules if m.startswith('cas_async.sim')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    assert out.strip() == "[]"
