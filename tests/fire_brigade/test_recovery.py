"""The Fire Brigade's recovery paths, each forced by a network that fails on cue.

Random loss almost never produces the moment a recovery path needs (a receiver that
gives up just before its giver arrives, a ``Meet`` that comes back from an earlier
partnership), so each test here drops or holds back chosen messages of one
partnership (see :mod:`tests.fire_brigade.censor`) and checks that the path ran,
that the bucket ledger held after every event (no bucket in two places, none lost),
and that every bucket was still delivered.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import pytest

from apps.fire_brigade.messages import (
    MESSAGES,
    Abandoned,
    Exchanged,
    Handover,
    Meet,
    Meeting,
    MeetingPoint,
    PartnerAnswer,
)
from apps.fire_brigade.strategy import Strategy
from cas_async import Message, MsgType
from cas_async.transport import Codec
from tests.fire_brigade.censor import (
    DELIVER,
    DROP,
    Hold,
    Outcome,
    Replace,
    Verdict,
    run_censored,
)
from tests.fire_brigade.helpers import SCENARIOS

SCENARIO = SCENARIOS / "thesis_5_8_1.toml"
SINKS = frozenset({3, 4})  # thesis_5_8_1: Generators 1-2, Sinks 3-4, Transporters 5-20
PATIENCE = 5.0


News = list[tuple[int, str, int, bool]]
"""Meetings' ends reaching Strategy layers from below: (robot, "Exchanged" or "Abandoned",
partner, has_bucket)."""


@pytest.fixture
def news(monkeypatch: pytest.MonkeyPatch) -> News:
    """Records every meeting's end as the Strategy layer hears of it."""
    seen: News = []
    hear = Strategy.store_intra_msg

    async def recording(self: Strategy, msg: Message) -> None:
        match msg:
            case Exchanged() | Abandoned():
                seen.append((self.robot_id, type(msg).__name__, msg.partner, msg.has_bucket))
        await hear(self, msg)

    monkeypatch.setattr(Strategy, "store_intra_msg", recording)
    return seen


def logged(caplog: pytest.LogCaptureFixture, text: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if text in r.getMessage()]


def assert_every_bucket_delivered(outcome: Outcome) -> None:
    assert outcome.delivered == outcome.target, f"{outcome.delivered}/{outcome.target} delivered"
    assert outcome.audits >= outcome.delivered  # the ledger was checked at every event


def test_lost_handover_notices_the_receiver_finds_the_bucket_in_its_hands(
    caplog: pytest.LogCaptureFixture, news: News
) -> None:
    """Every ``Handover`` is lost: each receiver gives up waiting, withdraws its hands, and
    finds the bucket there, so it reports the exchange after all."""
    caplog.set_level(logging.INFO)

    def no_handover(_now: float, _receiver: int, msg: Message) -> Verdict:
        return DROP if isinstance(msg, Handover) else DELIVER

    outcome = run_censored(SCENARIO, no_handover, [f"messaging.patience={PATIENCE}"])
    assert_every_bucket_delivered(outcome)
    assert outcome.dropped > 0
    assert len(outcome.transfers) >= outcome.target
    # Every giver asked in vain, and every receiver gave up waiting (bar the hand-overs
    # of the last seconds: the run ends with the last delivery).
    settled = [
        (giver, receiver)
        for t, _, giver, receiver in outcome.transfers
        if t < outcome.ended_at - 2 * PATIENCE
    ]
    assert len(settled) > outcome.target
    for giver, receiver in settled:
        assert logged(caplog, f"robot {giver} Task(L3): robot {receiver} never confirmed")
        assert logged(caplog, f"robot {receiver} Task(L3): robot {giver} silent for")
        assert (receiver, "Exchanged", giver, receiver not in SINKS) in news
    assert not logged(caplog, "hand-over refused")


@dataclass
class RefuseFirstHandOver:
    """The first partnership's receiver gives up at the meeting point before its giver
    even sets off; then the giver arrives and hears the receiver's old calls.

    The giver never learns where to meet until the receiver has given up (its answer to
    ``Meet`` is held back), and the receiver never hears the giver (the giver's calls
    are lost). The receiver's calls are held back until the giver is there: the giver
    then believes both are at the point and hands over into withdrawn hands.
    """

    deal: int | None = None
    giver: int = -1
    receiver: int = -1
    receiver_called_at: float | None = None
    giver_arrived: bool = False

    def __call__(self, _now: float, receiver: int, msg: Message) -> Verdict:
        if isinstance(msg, Meet) and msg.msg_type == MsgType.NEGOTIATION and self.deal is None:
            self.deal, self.giver, self.receiver = msg.deal, msg.robot_id, receiver
        elif isinstance(msg, MeetingPoint) and msg.deal == self.deal and receiver == self.giver:
            return Hold(self._receiver_gave_up)  # the meeting point, and its re-sent copies
        elif isinstance(msg, Meeting) and msg.deal == self.deal:
            if msg.robot_id == self.giver:
                self.giver_arrived = True
                return DROP
            if self.receiver_called_at is None:
                self.receiver_called_at = _now
            return Hold(lambda _: self.giver_arrived)
        return DELIVER

    def _receiver_gave_up(self, now: float) -> bool:
        called = self.receiver_called_at
        return called is not None and now > called + PATIENCE + 1.0


def test_a_hand_over_into_withdrawn_hands_is_refused_and_the_giver_keeps_the_bucket(
    caplog: pytest.LogCaptureFixture, news: News
) -> None:
    caplog.set_level(logging.INFO)
    rule = RefuseFirstHandOver()
    # The giver keeps asking for the meeting point (every 0.5 s) longer than the
    # receiver's patience lasts, so it is still asking when the answer is let through.
    overrides = [f"messaging.patience={PATIENCE}", "messaging.retries=40"]
    outcome = run_censored(SCENARIO, rule, overrides)
    assert rule.giver_arrived, "the giver never reached the meeting point"
    refused = logged(caplog, "hand-over refused")
    assert len(refused) == 1, refused
    assert f"robot {rule.giver}" in refused[0]  # the SimulationError names the giver
    # The receiver gave up (hands withdrawn, nothing in them) before the giver set off;
    # the giver still holds the bucket, and looks for another partner.
    assert logged(caplog, f"robot {rule.giver} silent for {PATIENCE:g} s: meeting given up")
    assert (rule.receiver, "Abandoned", rule.giver, False) in news
    assert (rule.giver, "Abandoned", rule.receiver, True) in news
    assert not any(
        status == "Exchanged" and {robot, partner} == {rule.giver, rule.receiver}
        for robot, status, partner, _ in news[
            : news.index((rule.giver, "Abandoned", rule.receiver, True))
        ]
    )
    assert_every_bucket_delivered(outcome)


@dataclass
class AcceptanceLost:
    """The first acceptance of a partnership never reaches the robot that asked."""

    deal: int | None = None
    asker: int = -1
    receiver: int = -1

    def __call__(self, _now: float, receiver: int, msg: Message) -> Verdict:
        if isinstance(msg, PartnerAnswer) and msg.msg_type == MsgType.ACCEPT:
            if self.deal is None:
                self.deal, self.asker, self.receiver = msg.corr_id, receiver, msg.robot_id
            if msg.corr_id == self.deal:
                return DROP  # and every copy the asker's re-sent requests bring back
        return DELIVER


def test_a_partner_that_never_sends_meet_is_given_up_by_the_receiver(
    caplog: pytest.LogCaptureFixture, news: News
) -> None:
    caplog.set_level(logging.INFO)
    rule = AcceptanceLost()
    outcome = run_censored(SCENARIO, rule, [f"run.seed={3}"])
    assert rule.deal is not None
    # The asker counted the receiver as silent and asked others ...
    assert logged(caplog, f"robot {rule.receiver} did not answer")
    # ... and the receiver, partnered without knowing it was in vain, gave the partnership up.
    assert logged(caplog, f"robot {rule.asker} never sent Meet: partnership abandoned")
    assert (rule.receiver, "Abandoned", rule.asker, False) in news  # free for others again
    assert_every_bucket_delivered(outcome)


@dataclass
class MeetFromAnEarlierDeal:
    """A giver's first ``Meet`` to a Sink is lost, but one copy comes back much later,
    once the two are partners again (a new deal): the Sink must refuse it."""

    deal: int | None = None
    giver: int = -1
    sink: int = -1
    later_deal: int | None = None
    refused: bool = False

    def __call__(self, _now: float, receiver: int, msg: Message) -> Verdict:
        if isinstance(msg, MeetingPoint):
            denied = msg.msg_type == MsgType.DENY and msg.robot_id == self.sink
            if denied and receiver == self.giver:
                self.refused = True
            return DELIVER
        if not isinstance(msg, Meet):
            return DELIVER
        if msg.msg_type == MsgType.NEGOTIATION and self.deal is None and receiver in SINKS:
            self.deal, self.giver, self.sink = msg.deal, msg.robot_id, receiver
            return Hold(lambda _: self.later_deal is not None)
        if msg.msg_type == MsgType.NEGOTIATION and msg.robot_id == self.giver:
            if msg.deal == self.deal:
                return DROP  # the re-sent copies: the giver gives this deal up
            if receiver == self.sink and self.later_deal is None:
                self.later_deal = msg.deal  # the held copy goes first, then this one
        return DELIVER


def test_a_meet_of_an_earlier_partnership_is_refused(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    rule = MeetFromAnEarlierDeal()
    outcome = run_censored(SCENARIO, rule)
    assert rule.deal is not None
    assert logged(caplog, f"robot {rule.sink} did not agree to meet")  # the first deal
    assert rule.later_deal is not None, "the giver never partnered with that Sink again"
    assert rule.refused, "the earlier deal's Meet was not refused"
    assert_every_bucket_delivered(outcome)


@dataclass
class PoisonedMeet:
    """The first ``Meet`` a giver sends arrives with other values: its retries are true.

    Message ids stay the giver's, so the runtime takes the poisoned copy for the real
    one: only the receiver's checks stand between the values and its layers.
    """

    x: float
    speed: float
    codec: Codec = field(default_factory=lambda: Codec.for_stack(5, MESSAGES))
    receiver: int = -1

    def __call__(self, _now: float, receiver: int, msg: Message) -> Verdict:
        if isinstance(msg, Meet) and msg.msg_type == MsgType.NEGOTIATION and self.receiver < 0:
            self.receiver = receiver
            poisoned = Meet(self.x, msg.y, msg.kind, self.speed, deal=msg.deal)
            poisoned.msg_type = msg.msg_type
            poisoned.msg_id, poisoned.robot_id = msg.msg_id, msg.robot_id
            poisoned.src_layer, poisoned.dst_layer = msg.src_layer, msg.dst_layer
            return Replace(self.codec.encode(poisoned))
        return DELIVER


@pytest.mark.parametrize("speed", [math.nan, math.inf, -1.0])
def test_a_meet_with_an_impossible_speed_is_refused_by_the_decoder(speed: float) -> None:
    # Issue 16: such a Meet made Group Activity raise, and the whole run failed.
    rule = PoisonedMeet(x=1.0, speed=speed)
    outcome = run_censored(SCENARIO, rule)
    assert outcome.replaced == 1
    assert outcome.refused[rule.receiver].get("decode.out_of_range") == 1
    assert_every_bucket_delivered(outcome)  # the giver asked again, and was answered


def test_a_meet_from_outside_the_world_is_denied_by_the_layer(
    caplog: pytest.LogCaptureFixture,
) -> None:
    rule = PoisonedMeet(x=1e9, speed=1.0)  # finite, so the decoder lets it through
    outcome = run_censored(SCENARIO, rule)
    assert outcome.replaced == 1
    assert logged(caplog, f"robot {rule.receiver} GroupActivity(L2): ignored Meet")
    assert logged(caplog, "a position outside the world")
    assert_every_bucket_delivered(outcome)
