"""The Fire Brigade's messages as types: the stack's list of them, the codec, each layer's dispatch.

Every meaning has its own class, with only the fields it needs. These tests keep it
that way: ``MESSAGES`` lists every class of the messages module once, no field is
optional (no ``X | None`` to recover with an assert), every message survives the
codec, and every layer, given a message of a class it does not take, logs it and
carries on: it never raises and never acts on it. Two small flows show the typed
messages a Strategy and a Task layer send.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import msgspec
import pytest

import apps.fire_brigade
from apps.fire_brigade import messages
from apps.fire_brigade.action import Action
from apps.fire_brigade.base import ACTION, GOAL, GROUP, STRATEGY, TASK, BrigadeLayer
from apps.fire_brigade.goal import Goal
from apps.fire_brigade.group_activity import GroupActivity
from apps.fire_brigade.messages import (
    MESSAGES,
    Abandoned,
    BucketMade,
    Carry,
    CompletionStatus,
    Destination,
    Exchanged,
    Give,
    Handover,
    HoldOut,
    Kind,
    MakeBucket,
    Meet,
    MeetAt,
    Meeting,
    MeetingPoint,
    Move,
    MoveBucket,
    Moved,
    PartnerAnswer,
    Partnered,
    RequestInfo,
    RequestPartner,
    RequestRobotsInRange,
    RobotInfo,
    RobotsInRange,
    Rotate,
    Take,
    Where,
    Withdraw,
)
from apps.fire_brigade.strategies import RandomStrategy, TimeStrategy
from apps.fire_brigade.task import Task
from cas_async import Clock, ConstantSpeed, Message, MsgType, Pose, VirtualClock
from cas_async._wire._message import message_fields
from cas_async.sim import Environment, SimulatedHands, SimulatedMiddleware
from cas_async.testing import LayerHarness, assert_roundtrip
from tests.fire_brigade.test_strategies import params

HEIGHT = 5
PEER = 2


def samples() -> list[Message]:
    """One message of each class, new each call (a message sent belongs to the runtime)."""
    return [
        RequestInfo(),
        RobotInfo(1.0, 2.0, Kind.SINK, 0.0),
        RequestPartner(1.0, 2.0, Kind.GENERATOR, bucket=3, to=Destination(4, 5.0, 9.0)),
        PartnerAnswer(Kind.TRANSPORTER),
        Meet(1.0, 2.0, Kind.TRANSPORTER, 4.5, deal=7),
        MeetingPoint(3.0, 4.0, deal=7),
        Meeting(7),
        Handover(3, deal=7),
        MoveBucket(bucket=3, to=Destination(4, 5.0, 9.0)),
        Partnered(partner=6, giver=True, bucket=3, to=Destination(4, 5.0, 9.0), deal=7),
        Carry(2.0, 3.0),
        MeetAt(partner=6, x=3.0, y=4.0, giver=False, bucket=3, to=Destination(4, 5.0, 9.0), deal=7),
        Exchanged(partner=6, bucket=3, has_bucket=True, x=3.0, y=4.0, to=Destination(4, 5.0, 9.0)),
        Moved(2.0, 3.0),
        Abandoned(6, has_bucket=False),
        RequestRobotsInRange(5.0),
        RobotsInRange(ids=[6, 8], xs=[3.0, 4.0], ys=[4.0, 5.0], x=1.0, y=2.0, speed=4.5),
        MakeBucket(),
        BucketMade(3, 1.0, 2.0),
        Where(),
        Rotate(3.0, 4.0),
        Move(3.0, 4.0),
        HoldOut(6),
        Withdraw(6, bucket=3),
        Give(3, partner=6),
        Take(3, partner=6),
        CompletionStatus(1.0, 2.0, heading=0.5, has_bucket=True),
    ]


# -- the list, and the classes ------------------------------------------------------------------


def test_messages_lists_every_message_class_of_the_module_once() -> None:
    defined = {
        value
        for value in vars(messages).values()
        if isinstance(value, type)
        and issubclass(value, Message)
        and value.__module__ == messages.__name__
    }
    assert len(set(MESSAGES)) == len(MESSAGES), "a class is listed twice"
    assert set(MESSAGES) == defined
    assert {cls.__name__ for cls in defined} <= set(messages.__all__)
    assert apps.fire_brigade.MESSAGES is MESSAGES


def test_the_samples_hold_one_message_of_each_class() -> None:
    assert [type(msg) for msg in samples()] == list(MESSAGES)


@pytest.mark.parametrize("cls", MESSAGES, ids=lambda cls: cls.__name__)
def test_no_field_is_optional(cls: type[Message]) -> None:
    # A field that may be None is a sentinel its reader must rule out again: a
    # question and its answer are two classes instead.
    info = msgspec.inspect.type_info(cls)
    assert isinstance(info, msgspec.inspect.StructType)
    optional = [
        field.name
        for field in info.fields
        if field.name in message_fields(cls)
        and isinstance(field.type, msgspec.inspect.UnionType)
        and any(isinstance(t, msgspec.inspect.NoneType) for t in field.type.types)
    ]
    assert optional == []


@pytest.mark.parametrize("msg", samples(), ids=lambda msg: type(msg).__name__)
def test_every_message_survives_the_codec(msg: Message) -> None:
    assert_roundtrip(msg, layers=HEIGHT, messages=MESSAGES)


# -- each layer, given a message it does not take ---------------------------------------------


def _action(clock: Clock) -> Action:
    environment = Environment()
    environment.add_robot(1, Pose(1.0, 1.0, 0.0), mobile=True)
    middleware = SimulatedMiddleware(
        environment, 1, clock, turn_rate=math.pi, speed_profile=ConstantSpeed(5.0)
    )
    return Action(params(), middleware, SimulatedHands(environment, 1, clock))


@dataclass(frozen=True)
class Case:
    """A layer, how a message reaches it, and the classes it takes that way."""

    make: Callable[[Clock], BrigadeLayer]
    level: int
    inject: str  # "above", "below" or "peer"
    takes: frozenset[type[Message]]
    negotiation: bool = False  # sent as a request (the Action layer's only input)


_INTERNAL = {
    GOAL: frozenset({Exchanged}),
    STRATEGY: frozenset({MoveBucket, Moved, Abandoned, Exchanged}),
    GROUP: frozenset({Partnered, Carry, Exchanged, Abandoned, Moved}),
    TASK: frozenset({MeetAt, Carry}),
    ACTION: frozenset[type[Message]](),
}
"""The classes each layer takes from a neighbour, from above or below."""

_EXTERNAL = {
    # Questions are taken as NEGOTIATIONs only: the samples are ACCEPTs.
    GOAL: frozenset({RobotInfo}),
    STRATEGY: frozenset({PartnerAnswer}),
    GROUP: frozenset[type[Message]](),
    TASK: frozenset({Meeting, Handover}),
    ACTION: frozenset[type[Message]](),
}
"""The classes each layer takes from another robot, sent as ACCEPT."""

_REQUESTS = frozenset(
    {RequestInfo, RequestRobotsInRange, MakeBucket, Where, Rotate, Move, HoldOut, Withdraw}
    | {Give, Take}
)
"""The requests the Action layer answers."""

_MAKE: dict[int, Callable[[Clock], BrigadeLayer]] = {
    GOAL: lambda _: Goal(params()),
    STRATEGY: lambda _: TimeStrategy(params()),
    GROUP: lambda _: GroupActivity(params()),
    TASK: lambda _: Task(params()),
    ACTION: _action,
}

CASES = {
    **{
        f"{name}-from-{inject}": Case(_MAKE[level], level, inject, _INTERNAL[level])
        for level, name in enumerate(("goal", "strategy", "group", "task", "action"))
        for inject in ("above", "below")
        if (inject == "above" and level > 0) or (inject == "below" and level < ACTION)
    },
    **{
        f"{name}-from-peer": Case(_MAKE[level], level, "peer", _EXTERNAL[level])
        for level, name in enumerate(("goal", "strategy", "group", "task", "action"))
    },
    "action-request-from-above": Case(_action, ACTION, "above", _REQUESTS, negotiation=True),
}


def _sent(h: LayerHarness, level: int) -> list[Message]:
    up = h.sent_up if level > 0 else []
    down = h.sent_down if level < ACTION else []
    return [*up, *down, *h.sent_to(PEER)]


@pytest.mark.cas_virtual
@pytest.mark.parametrize("case", CASES.values(), ids=CASES.keys())
async def test_a_layer_logs_a_message_of_a_class_it_does_not_take(
    case: Case, caplog: pytest.LogCaptureFixture
) -> None:
    clock = VirtualClock()
    wrong: Sequence[Message] = [msg for msg in samples() if type(msg) not in case.takes]
    assert wrong
    with caplog.at_level("WARNING", logger="cas_async"):
        async with LayerHarness(
            case.make(clock),
            level=case.level,
            height=HEIGHT,
            peers=[PEER],
            messages=MESSAGES,
            clock=clock,
        ) as h:
            for msg in wrong:
                if case.negotiation:
                    msg.msg_type = MsgType.NEGOTIATION
                if case.inject == "above":
                    h.from_above(msg)
                elif case.inject == "below":
                    h.from_below(msg)
                else:
                    h.from_peer(PEER, msg)
                await h.settle()
            assert _sent(h, case.level) == []  # nothing acted upon
    # Leaving the harness raised nothing: no layer failed, no message was dropped.
    logged = [record.getMessage() for record in caplog.records]
    for msg in wrong:
        name = type(msg).__name__
        found = [line for line in logged if f": ignored {name}(" in line]
        assert len(found) == 1, (name, logged)
    assert len(logged) == len(wrong), logged


# -- the typed messages of a search and of a solo leg -----------------------------------------


def body(msg: Message) -> tuple[object, ...]:
    """A message's class and fields, without the header the runtime stamped."""
    return (type(msg), *(getattr(msg, name) for name in message_fields(type(msg))))


@pytest.mark.cas_virtual
@pytest.mark.parametrize("answer", [MsgType.ACCEPT, MsgType.DENY], ids=["accepted", "refused"])
async def test_a_bucket_to_move_ends_in_a_partnership_or_a_leg_carried(answer: MsgType) -> None:
    in_range = RobotsInRange(ids=[PEER], xs=[5.0], ys=[5.0], x=5.0, y=1.0, speed=5.0)
    async with LayerHarness(
        RandomStrategy(params()), level=STRATEGY, height=HEIGHT, peers=[PEER], messages=MESSAGES
    ) as h:
        h.answer_at(ACTION, RequestRobotsInRange, lambda _: in_range)
        h.answer_peer(
            PEER, RequestPartner, lambda _: PartnerAnswer(Kind.TRANSPORTER, msg_type=answer)
        )
        to = Destination(3, 5.0, 19.0)
        h.from_above(MoveBucket(bucket=7, to=to))
        await h.settle()
        (asked,) = h.sent_to(PEER)
        assert body(asked) == (RequestPartner, 5.0, 1.0, Kind.TRANSPORTER, 7, to)
        if answer is MsgType.ACCEPT:  # the request's id is the partnership's deal
            expected = (Partnered, PEER, True, 7, to, asked.msg_id)
        else:  # one search_step (1.0) toward the sink
            expected = (Carry, 5.0, 2.0)
        assert [body(msg) for msg in h.sent_down] == [expected]


@pytest.mark.cas_virtual
async def test_a_leg_is_a_rotation_and_a_move_then_moved() -> None:
    def pose(x: float, y: float, heading: float) -> CompletionStatus:
        return CompletionStatus(x, y, heading, has_bucket=True)

    async with LayerHarness(Task(params()), level=TASK, height=HEIGHT, messages=MESSAGES) as h:
        h.answer_below(Where, lambda _: pose(1.0, 1.0, 0.0))
        h.answer_below(Rotate, lambda _: pose(1.0, 1.0, math.pi / 2))  # facing (1, 3)
        h.answer_below(Move, lambda _: pose(1.0, 3.0, math.pi / 2))
        h.from_above(Carry(1.0, 3.0))
        await h.settle()
        assert [body(msg) for msg in h.sent_down] == [
            (Where,),
            (Rotate, 1.0, 3.0),
            (Move, 1.0, 3.0),
        ]
        assert [body(msg) for msg in h.sent_up] == [(Moved, 1.0, 3.0)]
