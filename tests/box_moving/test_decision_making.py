"""The Decision-Making layer alone (LayerHarness): Fig. 21's states, conflicts between robots."""

from __future__ import annotations

import asyncio

import pytest

from apps.box_moving.base import DECISION_MAKING
from apps.box_moving.decision_making import DecisionMaking, State
from apps.box_moving.messages import (
    MESSAGES,
    CarryDone,
    ChangeStatus,
    GiveUp,
    Helping,
    MovedCount,
    ScanResult,
    SelectedObject,
    SelectionAnswer,
)
from cas_async import Message, MsgType
from cas_async.testing import LayerHarness
from tests.box_moving.helpers import body, params, sighting

NEAR, FAR = sighting(1, 2.0, 0.0), sighting(2, 6.0, 0.0)


def harness(
    layer: DecisionMaking,
    robot_id: int = 1,
    peers: tuple[int, ...] = (2,),
    task: MsgType = MsgType.ACCEPT,
) -> LayerHarness:
    """The layer over a Task layer that answers every ChangeStatus with ``task``."""
    h = LayerHarness(
        layer, level=DECISION_MAKING, height=4, robot_id=robot_id, peers=peers, messages=MESSAGES
    )

    def taken(msg: Message) -> Message:
        assert isinstance(msg, ChangeStatus)
        return ChangeStatus(msg.object, msg_type=task)

    h.answer_below(ChangeStatus, taken)
    return h


def accept(msg: Message) -> Message:
    assert isinstance(msg, SelectedObject)
    return SelectionAnswer(msg.obj)


def deny(msg: Message) -> Message:
    assert isinstance(msg, SelectedObject)
    return SelectionAnswer(msg.obj, msg_type=MsgType.DENY)


def sent(h: LayerHarness, name: str) -> int:
    """How many ``name`` messages the robot under test sent (to any layer)."""
    return h.robots.robots[0].message_counts()["internal"].get(name, 0)


@pytest.mark.cas_virtual
async def test_it_starts_by_scanning_and_selects_the_nearest_object_nobody_objects_to() -> None:
    layer = DecisionMaking(params(peers=(2,)))
    async with harness(layer) as h:
        h.answer_peer(2, SelectedObject, accept)
        await h.settle()
        assert layer.state is State.SELECTING
        assert sent(h, "Scan") == 1
        h.from_below(ScanResult(0.0, 0.0, [FAR, NEAR], moved=0))
        await h.settle()
        assert [m.obj for m in h.sent_to(2) if isinstance(m, SelectedObject)] == [1]
        (status,) = h.sent_down
        assert isinstance(status, ChangeStatus)
        assert body(status.object) == body(NEAR)
        assert layer.state.value == "selected"  # (mypy narrowed it to SELECTING above)
        assert sent(h, "Claim") == 1


@pytest.mark.cas_virtual
async def test_a_denied_object_gives_way_to_the_next_and_none_left_means_scanning_later() -> None:
    layer = DecisionMaking(params(peers=(2,), retry_interval=2.0))
    async with harness(layer) as h:
        h.answer_peer(2, SelectedObject, deny)
        await h.settle()
        h.from_below(ScanResult(0.0, 0.0, [NEAR, FAR], moved=0))
        await h.settle()
        assert [m.obj for m in h.sent_to(2) if isinstance(m, SelectedObject)] == [1, 2]
        assert h.sent_down == []
        assert layer.state is State.BACKING_OFF
        await asyncio.sleep(2.5)
        await h.settle()
        assert sent(h, "Scan") == 2


@pytest.mark.cas_virtual
async def test_it_refuses_an_object_it_selected_and_yields_to_a_lower_id_selecting_it_too() -> None:
    layer = DecisionMaking(params(peers=(1, 3)))
    async with harness(layer, robot_id=2, peers=(1, 3)) as h:
        h.answer_peer(1, SelectedObject, accept)
        h.answer_peer(3, SelectedObject, accept)
        await h.settle()
        free = await h.request_from_peer(3, SelectedObject(7))
        assert free.msg_type == MsgType.ACCEPT
        # Robot 2 is agreeing on object 1 right now: 3 (a higher id) is refused,
        # 1 (a lower id) wins it.
        layer.candidate = 1
        assert (await h.request_from_peer(3, SelectedObject(1))).msg_type == MsgType.DENY
        assert (await h.request_from_peer(1, SelectedObject(1))).msg_type == MsgType.ACCEPT
        assert layer.lost
        layer.candidate = None
        h.from_below(ScanResult(0.0, 0.0, [NEAR], moved=0))
        await h.settle()
        assert layer.selected is not None
        assert body(layer.selected) == body(NEAR)
        assert (await h.request_from_peer(1, SelectedObject(1))).msg_type == MsgType.DENY


@pytest.mark.cas_virtual
async def test_helping_another_robot_releases_the_selection_and_protects_the_helped_object() -> (
    None
):
    layer = DecisionMaking(params(peers=(2,)))
    async with harness(layer) as h:
        h.answer_peer(2, SelectedObject, accept)
        await h.settle()
        h.from_below(ScanResult(0.0, 0.0, [NEAR], moved=0))
        await h.settle()
        h.from_below(Helping(obj=9, leader=2))
        await h.settle()
        assert (layer.state, layer.selected, layer.helping) == (State.HELPING, None, 9)
        assert sent(h, "Unclaim") == 1
        assert (await h.request_from_peer(2, SelectedObject(9))).msg_type == MsgType.DENY
        assert (await h.request_from_peer(2, SelectedObject(1))).msg_type == MsgType.ACCEPT
        h.from_below(CarryDone(9))
        await h.settle()
        assert layer.state is State.SELECTING  # Fig. 21: no object selected: select one
        assert sent(h, "Scan") == 2


@pytest.mark.cas_virtual
async def test_an_object_nobody_can_lift_is_never_selected_again() -> None:
    layer = DecisionMaking(params(peers=(2,)))
    async with harness(layer) as h:
        h.answer_peer(2, SelectedObject, accept)
        await h.settle()
        h.from_below(ScanResult(0.0, 0.0, [NEAR, FAR], moved=0))
        await h.settle()
        h.from_below(GiveUp(1))
        await h.settle()
        h.from_below(ScanResult(0.0, 0.0, [NEAR, FAR], moved=0))
        await h.settle()
        assert [m.object.obj for m in h.sent_down if isinstance(m, ChangeStatus)] == [1, 2]


@pytest.mark.cas_virtual
async def test_it_stops_selecting_once_target_objects_are_moved() -> None:
    layer = DecisionMaking(params(peers=(2,), target=3))
    async with harness(layer) as h:
        await h.settle()
        h.from_below(MovedCount(3))
        h.from_below(ScanResult(0.0, 0.0, [NEAR], moved=3))
        await h.settle()
        assert layer.state is State.DONE
        assert layer.termination_condition()
        assert h.sent_down == []
        assert sent(h, "Scan") == 1


@pytest.mark.cas_virtual
async def test_a_selection_the_task_layer_refuses_is_released() -> None:
    layer = DecisionMaking(params(peers=(2,), retry_interval=2.0))
    async with harness(layer, task=MsgType.DENY) as h:
        h.answer_peer(2, SelectedObject, accept)
        await h.settle()
        h.from_below(ScanResult(0.0, 0.0, [NEAR, FAR], moved=0))
        await h.settle()
        assert [m.object.obj for m in h.sent_down if isinstance(m, ChangeStatus)] == [1]
        assert (layer.state, layer.selected) == (State.BACKING_OFF, None)
        assert (sent(h, "Claim"), sent(h, "Unclaim")) == (1, 1)
        h.from_below(Helping(obj=9, leader=2))  # what the refusal meant
        await h.settle()
        await asyncio.sleep(5.0)
        assert layer.state is State.HELPING
        assert sent(h, "Scan") == 1
