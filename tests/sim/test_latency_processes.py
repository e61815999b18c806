"""The Environment across processes: local robots, others' motions seen, items by courier.

Two Environments on one loop stand for two processes: ``a`` runs robot 1, ``b``
robot 2, and a courier takes each hand-over's steps from one to the other at their
instants, as a worker's network does (``cas_async.scenario._processes._network``).
"""

from __future__ import annotations

import asyncio
import math
import random

import pytest

from cas_async import Pose, SimulationError, UnknownRobotError, VirtualClock
from cas_async._time._deliveries import ITEM, MOTION, RECEIPT, Deliveries
from cas_async.sim import Environment, ItemLedger, Motion
from tests.sim.latency_support import (
    CREATED,
    REFUSED,
    RETURNED,
    SENT,
    TRANSFERRED,
    L,
    checked,
    drive,
    seen,
    started_clock,
    story,
    until,
    world,
)


class Courier:
    """Takes one process's hand-over steps to another's Environment, as a worker's network does.

    Both "processes" are Environments on this loop: each step is due at its instant, in
    its key's order, as the effects a worker receives are.
    """

    def __init__(self, clock: VirtualClock) -> None:
        self.clock = clock
        self.to: Environment | None = None
        self.steps: list[tuple[str, float]] = []

    def arrive(
        self, at: float, item: int, giver: int, receiver: int, sent: float, reach: float, n: int
    ) -> None:
        self.steps.append(("arrive", at))
        to = self.to
        assert to is not None
        action = lambda: to.item_arrives(item, giver, receiver, sent, reach, n)  # noqa: E731
        Deliveries.of().at(self.clock.loop_time_at(at), (ITEM, giver, n), action)

    def receipt(
        self,
        at: float,
        item: int,
        giver: int,
        receiver: int,
        n: int,
        refused: str | None,
        answer: int,
    ) -> None:
        self.steps.append(("receipt", at))
        to = self.to
        assert to is not None
        action = lambda: to.item_receipt(item, giver, receiver, n, refused)  # noqa: E731
        Deliveries.of().at(self.clock.loop_time_at(at), (RECEIPT, receiver, answer), action)


def two_processes(clock: VirtualClock) -> tuple[Environment, Environment, Courier, Courier]:
    """Robot 1 runs in ``a``, robot 2 in ``b``; both stand at the origin in both."""
    a, b = world(clock, (0, 0), (0, 0)), world(clock, (0, 0), (0, 0))
    to_b, to_a = Courier(clock), Courier(clock)
    a.set_local({1}, to_b)
    b.set_local({2}, to_a)
    to_b.to, to_a.to = b, a
    for env in (a, b):
        checked(env.items)  # the partial ledgers hold their invariant too
    return a, b, to_b, to_a


def whole_story(*ledgers: ItemLedger) -> ItemLedger:
    """What the world gathers: every process's events applied in order to one ledger."""
    events = sorted(
        (event.t, position, event)
        for position, event in enumerate(e for ledger in ledgers for e in ledger.events)
    )
    whole = ItemLedger(ids_by_creator=True)
    for _, _, event in events:
        whole.apply(event)
    whole.check()
    return whole


def test_set_local_names_robots_of_the_environment_and_comes_before_any_item() -> None:
    env = Environment()
    env.add_robot(1, Pose(0, 0, 0))
    with pytest.raises(UnknownRobotError, match="robot 5"):
        env.set_local({1, 5})
    env.create_item(1, 0.0)
    with pytest.raises(SimulationError, match="before any item is made"):
        env.set_local({1})


@pytest.mark.cas_virtual
async def test_another_process_robot_moves_here_as_it_is_seen() -> None:
    clock = started_clock()
    a, b, _, _ = two_processes(clock)

    def publish(robot: int, motion: Motion, start: float) -> None:  # as a worker's window does
        action = lambda: a.see_motion(robot, motion, start)  # noqa: E731
        Deliveries.of().at(clock.loop_time_at(start + L), (MOTION, robot, 1), action)

    b.watch_motions(publish)
    await until(clock, 1.0)
    drive(b, 2, 1.0, 10, 0)
    await until(clock, 1.0 + L / 2)
    assert a.pose_at(2, 1.0 + L / 2) == Pose(0, 0, 0)  # known here only once seen
    assert a.motion_of(2)[1] == -math.inf
    await until(clock, 1.0 + L)
    assert a.motion_of(2)[1] == 1.0  # its motion here, from when it started
    assert a.pose_at(2, 2.0) == Pose(1.0, 0.0, 0.0)
    assert seen(a, 1, 2.0) == {2: (1.0, 0.0)}
    assert a.distance_travelled(2, 2.0) == 1.0


@pytest.mark.cas_virtual
async def test_a_hand_over_to_another_process_arrives_there_and_leaves_here() -> None:
    clock = started_clock()
    a, b, to_b, to_a = two_processes(clock)
    item = a.create_item(1, 0.0)
    await until(clock, 1.0)
    await a.send_item(item, 1, 2, 1.0, reach=0.1)
    assert clock.now() == 1.0 + 2 * L
    assert (to_b.steps, to_a.steps) == ([("arrive", 1.0 + L)], [("receipt", 1.0 + 2 * L)])
    assert b.items.held_by(2) == (item,)
    assert a.items.in_transit == 0
    assert story(a.items) == [(0.0, CREATED, 1), (1.0, SENT, 1)]
    assert story(b.items) == [(1.0 + L, TRANSFERRED, 2)]
    assert whole_story(a.items, b.items).holder(item) == 2


@pytest.mark.cas_virtual
async def test_a_hand_over_refused_in_another_process_is_back_with_its_giver_at_t_plus_2l() -> None:
    clock = started_clock()
    a, b, _, _ = two_processes(clock)
    b.refuse_from(2, 1)
    item = a.create_item(1, 0.0)
    await until(clock, 1.0)
    with pytest.raises(SimulationError, match="robot 2 does not take items from robot 1"):
        await asyncio.wait_for(a.send_item(item, 1, 2, 1.0, reach=0.1), 10.0)
    assert clock.now() == 1.0 + 2 * L
    assert a.items.held_by(1) == (item,)
    assert (a.items.in_transit, b.items.in_transit) == (0, 0)
    assert story(a.items) == [(0.0, CREATED, 1), (1.0, SENT, 1), (1.0 + 2 * L, RETURNED, 1)]
    assert story(b.items) == [(1.0 + L, REFUSED, 2)]
    whole = whole_story(a.items, b.items)
    assert [event.kind for event in whole.events] == [CREATED, SENT, REFUSED, RETURNED]
    assert whole.holder(item) == 1


@pytest.mark.cas_virtual
async def test_an_item_refused_in_another_process_may_be_handed_there_again() -> None:
    clock = started_clock()
    a, b, _, _ = two_processes(clock)
    b.refuse_from(2, 1)
    item = a.create_item(1, 0.0)
    with pytest.raises(SimulationError, match="does not take items"):
        await asyncio.wait_for(a.send_item(item, 1, 2, 0.0, reach=0.1), 10.0)
    b.accept_from(2, 1)
    await asyncio.wait_for(a.send_item(item, 1, 2, clock.now(), reach=0.1), 10.0)
    assert b.items.held_by(2) == (item,)
    # ...and handed back the other way, to the process it came from.
    await asyncio.wait_for(b.send_item(item, 2, 1, clock.now(), reach=0.1), 10.0)
    assert a.items.held_by(1) == (item,)
    whole = whole_story(a.items, b.items)
    assert whole.holder(item) == 1
    assert whole.transfers == 2


@pytest.mark.cas_virtual
async def test_items_between_processes_keep_the_invariant_through_many_hand_overs() -> None:
    clock, rng = started_clock(), random.Random(5)
    a, b, _, _ = two_processes(clock)
    envs, hands = {1: a, 2: b}, {1: a.create_item(1, 0.0), 2: b.create_item(2, 0.0)}
    outcomes = []
    for _ in range(12):
        if rng.random() < 0.4:
            b.refuse_from(2, 1)
            a.refuse_from(1, 2)
        else:
            b.accept_from(2, 1)
            a.accept_from(1, 2)
        holder = rng.choice([r for r in (1, 2) if envs[r].items.held_by(r)])
        item = envs[holder].items.held_by(holder)[0]
        try:
            await asyncio.wait_for(
                envs[holder].send_item(item, holder, 3 - holder, clock.now(), reach=0.1), 10.0
            )
            outcomes.append("taken")
        except SimulationError:
            outcomes.append("refused")
    assert {"taken", "refused"} <= set(outcomes)
    whole = whole_story(a.items, b.items)
    assert sorted(whole.held_by(1) + whole.held_by(2)) == sorted(hands.values())
    assert whole.in_transit == 0
