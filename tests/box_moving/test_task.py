"""The Task layer alone (LayerHarness): HelpRequest, finding a partner, and answering others."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import pytest

from apps.box_moving.base import ACTION, TASK
from apps.box_moving.messages import (
    MESSAGES,
    Assignment,
    CarryDone,
    ChangeStatus,
    Dismiss,
    Dismissed,
    GiveUp,
    Helping,
    Locate,
    Located,
    OfferHelp,
    PartnerAnswer,
    Released,
    RequestPartner,
    Role,
)
from apps.box_moving.task import Phase, Task
from cas_async import Message, MsgType
from cas_async.testing import LayerHarness
from tests.box_moving.helpers import bodies, body, params, sighting

LIGHT, HEAVY = sighting(1, weight=4.0), sighting(2, weight=14.0)
# Robot 3 stands nearer than robot 2: it is asked first.
AROUND = Located(ids=[3, 2], xs=[1.0, 4.0], ys=[0.0, 0.0], x=0.0, y=0.0)


def harness(layer: Task, robot_id: int = 1) -> LayerHarness:
    peers = tuple(peer for peer in (1, 2, 3) if peer != robot_id)
    h = LayerHarness(layer, level=TASK, height=4, robot_id=robot_id, peers=peers, messages=MESSAGES)
    h.answer_at(ACTION, Locate, lambda _: AROUND)
    return h


def answering(how: MsgType, *, able: bool = True) -> Callable[[Message], Message]:
    def answer(msg: Message) -> Message:
        assert isinstance(msg, RequestPartner)
        return PartnerAnswer(msg.object.obj, able, 6.0, msg_type=how)

    return answer


@pytest.mark.cas_virtual
async def test_an_object_within_the_payload_is_carried_alone() -> None:
    layer = Task(params(peers=(2, 3)))
    async with harness(layer) as h:
        h.from_above(ChangeStatus(LIGHT))
        await h.settle()
        assert bodies(h.sent_down) == [body(Assignment(LIGHT, Role.SOLO))]
        assert h.sent_to(2) == h.sent_to(3) == []
        assert layer.phase is Phase.SOLO


@pytest.mark.cas_virtual
async def test_a_heavy_object_takes_the_nearest_robot_that_accepts() -> None:
    layer = Task(params(peers=(2, 3)))
    async with harness(layer) as h:
        h.answer_peer(3, RequestPartner, answering(MsgType.DENY))
        h.answer_peer(2, RequestPartner, answering(MsgType.ACCEPT))
        h.from_above(ChangeStatus(HEAVY))
        await h.settle()
        assert [type(m).__name__ for m in h.sent_to(3)] == ["RequestPartner"]
        assert [type(m).__name__ for m in h.sent_to(2)] == ["RequestPartner"]
        assert bodies(h.sent_down) == [
            body(Assignment(HEAVY, Role.LEADER, partner=2, partner_payload=6.0))
        ]
        assert (layer.phase, layer.partner) == (Phase.LEADING, 2)


@pytest.mark.cas_virtual
async def test_when_all_are_busy_it_asks_again_after_the_retry_interval() -> None:
    layer = Task(params(peers=(2, 3), retry_interval=2.0))
    async with harness(layer) as h:
        h.answer_peer(3, RequestPartner, answering(MsgType.DENY))
        h.answer_peer(2, RequestPartner, answering(MsgType.DENY))
        h.from_above(ChangeStatus(HEAVY))
        await h.settle()
        assert len(h.sent_to(2)) == 1
        assert layer.phase is Phase.WAITING
        await asyncio.sleep(2.5)
        await h.settle()
        assert len(h.sent_to(2)) == 2


@pytest.mark.cas_virtual
async def test_an_object_no_pair_can_lift_is_given_up() -> None:
    layer = Task(params(peers=(2, 3)))
    async with harness(layer) as h:
        h.answer_peer(3, RequestPartner, answering(MsgType.DENY, able=False))
        h.answer_peer(2, RequestPartner, answering(MsgType.DENY, able=False))
        h.from_above(ChangeStatus(HEAVY))
        await h.settle()
        assert bodies(h.sent_up) == [body(GiveUp(HEAVY.obj))]
        assert layer.phase is Phase.IDLE


@pytest.mark.cas_virtual
async def test_a_free_robot_accepts_and_tells_its_layers_it_helps() -> None:
    layer = Task(params(peers=(2, 3), payload=6.0))
    async with harness(layer) as h:
        answer = await h.request_from_peer(2, RequestPartner(HEAVY, 10.0))
        assert isinstance(answer, PartnerAnswer)
        assert (answer.msg_type, answer.able, answer.payload) == (MsgType.ACCEPT, True, 6.0)
        await h.settle()
        assert bodies(h.sent_up) == [body(Helping(HEAVY.obj, leader=2))]
        assert bodies(h.sent_down) == [
            body(Assignment(HEAVY, Role.HELPER, partner=2, partner_payload=10.0))
        ]
        weak = await h.request_from_peer(3, RequestPartner(sighting(5, weight=20.0), 6.0))
        assert isinstance(weak, PartnerAnswer)
        assert (weak.msg_type, weak.able) == (MsgType.DENY, False)


@pytest.mark.cas_virtual
async def test_of_two_robots_waiting_for_each_other_the_lower_id_wins() -> None:
    layer = Task(params(peers=(1, 3)))
    async with harness(layer, robot_id=2) as h:
        h.answer_peer(3, RequestPartner, answering(MsgType.DENY))
        h.answer_peer(1, RequestPartner, answering(MsgType.DENY))
        h.from_above(ChangeStatus(HEAVY))
        await h.settle()
        assert layer.phase is Phase.WAITING
        other = sighting(8, weight=12.0)
        higher = await h.request_from_peer(3, RequestPartner(other, 6.0))
        assert higher.msg_type == MsgType.DENY
        lower = await h.request_from_peer(1, RequestPartner(other, 10.0))
        assert lower.msg_type == MsgType.ACCEPT
        assert (layer.phase, layer.partner) == (Phase.HELPING, 1)
        await asyncio.sleep(5.0)  # its own retry is off: it no longer waits
        await h.settle()
        assert len(h.sent_to(3)) == 1


@pytest.mark.cas_virtual
async def test_a_busy_robot_offers_its_help_once_its_carry_is_done() -> None:
    layer = Task(params(peers=(2, 3)))
    async with harness(layer) as h:
        h.answer_peer(2, OfferHelp, lambda m: OfferHelp(getattr(m, "obj", 0), 6.0))
        h.from_above(ChangeStatus(LIGHT))
        await h.settle()
        busy = await h.request_from_peer(2, RequestPartner(HEAVY, 6.0))
        assert (busy.msg_type, getattr(busy, "able", None)) == (MsgType.DENY, True)
        h.from_below(CarryDone(LIGHT.obj))
        await h.settle()
        (offer,) = h.sent_to(2)
        assert isinstance(offer, OfferHelp)
        assert (offer.obj, offer.msg_type) == (HEAVY.obj, MsgType.NEGOTIATION)
        assert (layer.phase, layer.partner) == (Phase.HELPING, 2)
        # Helping goes up before the finished carry: Decision-Making does not select meanwhile.
        assert bodies(h.sent_up) == [
            body(Helping(HEAVY.obj, leader=2)),
            body(CarryDone(LIGHT.obj)),
        ]


@pytest.mark.cas_virtual
async def test_a_dismissed_helper_is_free_again() -> None:
    layer = Task(params(peers=(2, 3)))
    async with harness(layer) as h:
        await h.request_from_peer(2, RequestPartner(HEAVY, 6.0))
        answer = await h.request_from_peer(2, Dismiss(HEAVY.obj))
        assert answer.msg_type == MsgType.ACCEPT
        await h.settle()
        assert layer.phase is Phase.IDLE
        assert body(h.sent_up[-1]) == body(Released(HEAVY.obj))
        assert body(h.sent_down[-1]) == body(Dismissed(HEAVY.obj))
