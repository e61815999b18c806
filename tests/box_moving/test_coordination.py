"""The Coordination layer alone (LayerHarness): AgreeOnBalancing, InformAction, keeping in step."""

from __future__ import annotations

import asyncio

import pytest

from apps.box_moving.base import COORDINATION
from apps.box_moving.coordination import Coordination
from apps.box_moving.coordination_fixed import FixedSideCoordination
from apps.box_moving.messages import (
    MESSAGES,
    Assignment,
    Balance,
    Balanced,
    CarryDone,
    CarryOut,
    Go,
    MovedCount,
    Position,
    Ready,
    Release,
    Role,
    Side,
    Where,
)
from cas_async import Message, MsgType
from cas_async.testing import LayerHarness
from tests.box_moving.helpers import bodies, body, params, sighting

# An object of size 1 at (5, 5), weight 14, going to (9, 5): two legs of 2.
HEAVY = sighting(2, 5.0, 5.0, weight=14.0)
WEST, EAST, NORTH = (4.0, 5.0), (6.0, 5.0), (5.0, 7.0)


def harness(layer: Coordination, at: tuple[float, float] = WEST) -> LayerHarness:
    h = LayerHarness(layer, level=COORDINATION, height=4, peers=[2], messages=MESSAGES)
    h.answer_below(Where, lambda _: Position(at[0], at[1], 0.0))
    return h


@pytest.mark.parametrize(
    ("leader_at", "helper_at", "sides"),
    [
        (WEST, EAST, (Side.WEST, Side.EAST)),  # each at its nearest side
        (EAST, WEST, (Side.EAST, Side.WEST)),
        (NORTH, (5.0, 2.0), (Side.NORTH, Side.SOUTH)),
        # Both come from the east: across the north-south axis neither walks round.
        ((8.0, 5.2), (8.0, 4.8), (Side.NORTH, Side.SOUTH)),
        ((8.0, 4.8), (8.0, 5.2), (Side.SOUTH, Side.NORTH)),
    ],
    ids=["west-east", "east-west", "north-south", "both-east", "both-east-swapped"],
)
def test_each_robot_takes_its_nearest_side_or_the_pair_that_is_soonest_there(
    leader_at: tuple[float, float], helper_at: tuple[float, float], sides: tuple[Side, Side]
) -> None:
    rule = Coordination(params())
    assert rule.choose_sides(1, leader_at, 2, helper_at, HEAVY) == sides


@pytest.mark.parametrize(("leader", "helper"), [(1, 2), (2, 1)])
def test_the_fixed_rule_puts_the_lower_id_west_wherever_the_robots_stand(
    leader: int, helper: int
) -> None:
    sides = FixedSideCoordination(params()).choose_sides(leader, EAST, helper, WEST, HEAVY)
    assert sides == ((Side.WEST, Side.EAST) if leader < helper else (Side.EAST, Side.WEST))


@pytest.mark.cas_virtual
async def test_a_solo_carry_lifts_from_the_nearest_side_at_the_loaded_speed() -> None:
    light = sighting(1, 5.0, 5.0, weight=4.0)
    async with harness(Coordination(params()), at=NORTH) as h:
        h.from_above(Assignment(light, Role.SOLO))
        await h.settle()
        # payload 10, weight 4, slowdown 0.5: 1 - 0.5 * 0.4 of the speed
        assert bodies(h.sent_down) == [
            body(Where()),
            body(CarryOut(light, Role.SOLO, Side.NORTH, 0.8)),
        ]


def balanced(msg: Message) -> Message:
    assert isinstance(msg, Balance)
    return Balanced(msg.obj, Side.WEST, Side.EAST, min(msg.speed, 0.5))


@pytest.mark.cas_virtual
async def test_the_leader_proposes_and_informs_action_of_what_the_helper_agreed() -> None:
    async with harness(Coordination(params())) as h:
        h.answer_peer(2, Balance, balanced)
        h.from_above(Assignment(HEAVY, Role.LEADER, partner=2, partner_payload=6.0))
        await h.settle()
        (proposal,) = h.sent_to(2)
        assert isinstance(proposal, Balance)
        # weight 14 shared by payloads 10 + 6: each at 1 - 0.5 * 14 / 16 of its speed
        assert (proposal.x, proposal.y, proposal.speed) == (4.0, 5.0, 1 - 0.5 * 14 / 16)
        assert body(h.sent_down[-1]) == body(CarryOut(HEAVY, Role.LEADER, Side.WEST, 0.5, 2))


@pytest.mark.cas_virtual
async def test_the_helper_chooses_the_sides_and_the_slower_speed() -> None:
    async with harness(Coordination(params(speed=0.6)), at=WEST) as h:
        h.from_above(Assignment(HEAVY, Role.HELPER, partner=2, partner_payload=10.0))
        await h.settle()
        answer = await h.request_from_peer(2, Balance(HEAVY.obj, 6.0, 5.0, 1.0))
        assert isinstance(answer, Balanced)
        speed = 0.6 * (1 - 0.5 * 14 / 20)  # payloads 10 + 10
        assert (answer.leader_side, answer.helper_side) == (Side.EAST, Side.WEST)
        assert answer.speed == pytest.approx(speed)
        await h.settle()
        carry = h.sent_down[-1]
        assert isinstance(carry, CarryOut)
        assert (carry.role, carry.side, carry.partner) == (Role.HELPER, Side.WEST, 2)


@pytest.mark.cas_virtual
async def test_a_balance_that_overtakes_the_assignment_is_answered_once_it_comes() -> None:
    async with harness(Coordination(params())) as h:
        asking = asyncio.ensure_future(h.request_from_peer(2, Balance(HEAVY.obj, 6.0, 5.0, 1.0)))
        await h.settle()
        assert not asking.done()
        h.from_above(Assignment(HEAVY, Role.HELPER, partner=2, partner_payload=10.0))
        answer = await asking
        assert answer.msg_type == MsgType.ACCEPT


@pytest.mark.cas_virtual
async def test_the_leader_starts_each_leg_when_both_are_ready_then_the_put_down() -> None:
    layer = Coordination(params(sync_margin=0.2, leg_length=2.0))
    async with harness(layer) as h:
        h.answer_peer(2, Balance, balanced)
        h.from_above(Assignment(HEAVY, Role.LEADER, partner=2, partner_payload=6.0))
        await h.settle()
        h.from_below(Ready(HEAVY.obj, 0))
        await h.settle()
        assert not [m for m in h.sent_down if isinstance(m, Go)]  # the helper is not ready yet
        h.from_peer(2, Ready(HEAVY.obj, 0))
        await h.settle()
        now = layer.clock.now()
        legs = [(m.leg, m.x, m.y, m.at) for m in h.sent_down if isinstance(m, Go)]
        assert legs == [(0, 7.0, 5.0, now + 0.2)]
        assert [(m.leg, m.at) for m in h.sent_to(2) if isinstance(m, Go)] == [(0, now + 0.2)]
        for leg in (1, 2):
            h.from_below(Ready(HEAVY.obj, leg))
            h.from_peer(2, Ready(HEAVY.obj, leg))
            await h.settle()
        assert [(m.leg, m.x) for m in h.sent_down if isinstance(m, Go)] == [(0, 7.0), (1, 9.0)]
        assert [type(m).__name__ for m in h.sent_to(2)][-1] == "Release"
        assert isinstance(h.sent_down[-1], Release)
        h.from_below(CarryDone(HEAVY.obj))
        h.from_below(MovedCount(1))
        await h.settle()
        assert bodies(h.sent_up) == [body(CarryDone(HEAVY.obj)), body(MovedCount(1))]
        assert layer.joint is None


@pytest.mark.cas_virtual
async def test_the_helper_forwards_its_readiness_and_the_leaders_steps() -> None:
    async with harness(Coordination(params())) as h:
        h.from_above(Assignment(HEAVY, Role.HELPER, partner=2, partner_payload=10.0))
        await h.settle()
        await h.request_from_peer(2, Balance(HEAVY.obj, 6.0, 5.0, 1.0))
        h.from_below(Ready(HEAVY.obj, 0))
        await h.settle()
        assert bodies(h.sent_to(2))[-1] == body(Ready(HEAVY.obj, 0))
        h.from_peer(2, Go(HEAVY.obj, 0, 7.0, 5.0, 3.0))
        h.from_peer(2, Release(HEAVY.obj, 9.0))
        await h.settle()
        assert bodies(h.sent_down)[-2:] == [
            body(Go(HEAVY.obj, 0, 7.0, 5.0, 3.0)),
            body(Release(HEAVY.obj, 9.0)),
        ]
