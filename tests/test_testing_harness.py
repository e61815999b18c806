"""LayerHarness: one layer between scripted neighbours and peers, in the real runtime."""

from __future__ import annotations

from collections.abc import Hashable

import pytest

from apps.fire_brigade import TimeStrategy
from apps.fire_brigade.base import ACTION
from apps.fire_brigade.messages import (
    MESSAGES,
    Destination,
    MoveBucket,
    RequestPartner,
    RequestRobotsInRange,
    RobotsInRange,
)
from cas_async import Layer, LayerError, Message, MsgType, message
from cas_async.testing import LayerHarness
from tests.fire_brigade.test_strategies import params


@pytest.mark.cas_virtual
async def test_a_strategy_layer_asks_the_best_partner_first() -> None:
    near = RobotsInRange(ids=[11, 12], xs=[5.0, 5.0], ys=[-2.0, 5.0], x=5.0, y=1.0, speed=5.0)
    async with LayerHarness(
        TimeStrategy(params()), level=1, height=5, peers=[11, 12], messages=MESSAGES
    ) as h:
        h.answer_at(ACTION, RequestRobotsInRange, lambda _: near)
        h.from_above(MoveBucket(bucket=7, to=Destination(2, 5.0, 19.0)))
        await h.settle()
        (asked,) = h.sent_to(12)  # ahead, on the way to the sink: the best partner
        assert isinstance(asked, RequestPartner)
        assert (asked.bucket, asked.msg_type) == (7, MsgType.NEGOTIATION)
        assert h.sent_to(11) == []


@message
class Job(Message):
    n: int


@message
class Done(Message):
    n: int


class Worker(Layer):
    """Takes jobs from above and from peers; asks below; reports up; fails on n < 0."""

    async def store_intra_msg(self, msg: Message) -> None:
        match msg:
            case Job(n=n) if n < 0:
                raise ValueError(f"job {n}")
            case Job(n=n):
                done = await self.request_down(Job(n), reply=Done)
                self.send_up(Done(done.n))

    def get_msg_reply(self, msg: Message) -> Message | None:
        match msg:
            case Job(n=n):
                return Done(n * 10)
        return None


@pytest.mark.cas_virtual
async def test_the_harness_scripts_neighbours_and_peers_and_records_what_the_layer_did() -> None:
    async with LayerHarness(Worker(), level=1, height=3, peers=[5], messages=[Job, Done]) as h:
        h.answer_below(Job, lambda m: Done(m.n + 1) if isinstance(m, Job) else None)
        h.from_above(Job(1))
        await h.settle()
        assert [type(m).__name__ for m in h.sent_down] == ["Job"]
        assert [(type(m).__name__, getattr(m, "n", None)) for m in h.sent_up] == [("Done", 2)]
        answer = await h.request_from_peer(5, Job(4))
        assert isinstance(answer, Done)
        assert answer.n == 40


@pytest.mark.cas_virtual
async def test_a_layer_that_fails_under_the_harness_fails_the_test() -> None:
    with pytest.raises(LayerError, match="job -1"):
        async with LayerHarness(Worker(), level=0, height=2, messages=[Job, Done]) as h:
            h.from_below(Job(-1))
            await h.settle()


def test_the_harness_names_what_does_not_exist() -> None:
    harness = LayerHarness(Worker(), level=0, height=2, peers=[3], messages=[Job, Done])
    with pytest.raises(ValueError, match="no layer above"):
        harness.from_above(Job(1))
    with pytest.raises(ValueError, match="robot 4 is not a peer"):
        harness.sent_to(4)
    with pytest.raises(ValueError, match="level 2 is not in a stack of 2"):
        LayerHarness(Worker(), level=2, height=2)


@pytest.mark.cas_virtual
async def test_a_failing_test_body_is_not_hidden_by_what_the_harness_finds() -> None:
    with pytest.raises(AssertionError, match="the test's own") as caught:
        async with LayerHarness(Worker(), level=0, height=2, messages=[Job, Done]) as h:
            h.from_below(Job(-1))
            await h.settle()
            raise AssertionError("the test's own")
    assert "job -1" in "".join(caught.value.__notes__)


@pytest.mark.cas_virtual
async def test_the_harness_takes_the_drops_a_test_expects() -> None:
    async with LayerHarness(
        Worker(), level=0, height=2, messages=[Job, Done], allowed_drops={"unknown_robot"}
    ) as h:
        h.layer.send(9, Job(1))  # nobody is robot 9
        await h.settle()


class Later(Layer):
    """Sends Job(1) to robot 5 one simulated second after it starts, and Job(2) a second later."""

    def __init__(self) -> None:
        self.sent = 0

    async def inner_process(self) -> None:
        if self.sent < 2 and self.wake_due("job") is None:
            self.wake_after(1.0, "job")

    async def on_timer(self, key: Hashable) -> None:
        self.sent += 1
        self.send(5, Job(self.sent))


@pytest.mark.cas_virtual
async def test_settle_leaves_time_where_it_is_and_advance_moves_it_to_the_timers() -> None:
    async with LayerHarness(Later(), peers=[5], messages=[Job, Done]) as h:
        clock = h.robots.robots[0].clock
        await h.settle()
        assert (h.sent_to(5), clock.now()) == ([], 0.0)  # the timer is a second ahead
        await h.advance(0.5)
        assert (h.sent_to(5), clock.now()) == ([], 0.5)
        await h.advance(0.5)  # onto the timer's instant: it goes off, its message arrives
        assert ([m.n for m in h.sent_to(5) if isinstance(m, Job)], clock.now()) == ([1], 1.0)
        await h.advance(10.0)
        assert ([m.n for m in h.sent_to(5) if isinstance(m, Job)], clock.now()) == ([1, 2], 11.0)


async def test_advance_refuses_a_negative_time_and_a_harness_not_started() -> None:
    harness = LayerHarness(Later(), peers=[5], messages=[Job, Done])
    with pytest.raises(RuntimeError, match="start the harness first"):
        await harness.advance(1.0)
    with pytest.raises(ValueError, match="seconds must be >= 0, got -1"):
        await harness.advance(-1.0)
