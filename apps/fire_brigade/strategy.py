"""The Strategy layer (thesis Fig. 29): finding a partner for the bucket.

With a bucket to move (``MoveBucket`` from the Goal layer) it asks the Action
layer for the robots in range (``RequestRobotsInRange``, answered with
``RobotsInRange``), ranks them with :meth:`Strategy.choose` (the one method a
strategy variant overrides, §5.7), and asks them in that order (``RequestPartner``)
until one accepts (``PartnerAnswer``). Then it hands the partnership to the Group
Activity layer (``Partnered``). When nobody accepts, a Transporter carries the
bucket one ``search_step`` toward its sink (``Carry``, done when ``Moved`` comes
back) and looks again; a Generator, which cannot move, waits ``retry_interval``
and asks again within a wider radius.

It also answers other robots' requests: an idle Transporter (no bucket, no
partner) and a Sink accept; everyone else refuses. Partnerships are not
interruptible: they last until the bucket changed hands (``Exchanged``), which
is passed up to the Goal layer, or until a layer below gives up on a silent
partner (``Abandoned``): a giver then looks for another partner, a receiver is
free again.

Over a lossy network a request left unanswered for ``timeout`` is sent again,
unchanged (``resend``: the other robot handles it once and repeats its answer);
after ``retries`` more attempts the robot asked counts as silent, like a refusal.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass

from cas_async import Message, MsgType, SpeedProfile

from .base import ACTION, BrigadeLayer, Params, Point
from .estimate import distance
from .messages import (
    Abandoned,
    Carry,
    Destination,
    Exchanged,
    Kind,
    MoveBucket,
    Moved,
    PartnerAnswer,
    Partnered,
    RequestPartner,
    RequestRobotsInRange,
    RobotsInRange,
)

__all__ = ["Candidate", "SearchView", "Strategy"]

_ARRIVED = 1e-9
"""Distance below which a carrier stands at its sink."""


@dataclass(frozen=True, slots=True)
class Candidate:
    """A robot in range that might take the bucket."""

    robot: int
    at: Point


@dataclass(frozen=True, slots=True)
class SearchView:
    """What a strategy knows when it ranks partners.

    Attributes:
        robot: this robot's id.
        kind: this robot's kind (Generators cannot carry the bucket themselves).
        here: where this robot is.
        carrying: this robot's speed profile with the bucket from now on (its
            fatigue so far included); ``None`` for an immobile robot.
        sink: the destination's id; ``sink_at`` its position.
        candidates: robots in range, nearest first; the destination sink among them
            when in range; robots known not to take buckets (other stations) left out.
        params: this robot's parameters (speeds and deceleration of a fresh partner).
    """

    robot: int
    kind: Kind
    here: Point
    carrying: SpeedProfile | None
    sink: int
    sink_at: Point
    candidates: tuple[Candidate, ...]
    params: Params

    @property
    def fresh_partner(self) -> SpeedProfile:
        """An empty transporter's profile (it moves at full speed)."""
        return self.params.empty()

    @property
    def loaded_partner(self) -> SpeedProfile:
        """A transporter's profile once it takes the bucket (fresh fatigue)."""
        return self.params.carrying()

    def sink_in_range(self) -> Candidate | None:
        """The destination, when it is among the candidates."""
        return next((c for c in self.candidates if c.robot == self.sink), None)


class Strategy(BrigadeLayer):
    """Partner selection; subclasses decide the order in which partners are asked."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.bucket = -1
        self.sink = -1
        self.sink_at: Point = (0.0, 0.0)
        self.here: Point = (0.0, 0.0)
        self.searching = False  # between MoveBucket and a partner or a carried leg
        self.to_ask: list[int] = []
        self.asked = -1  # the robot whose answer is awaited
        self.asked_in = -1  # the msg_id of that request: its answer's corr_id
        self.question: RequestPartner | None = None  # that request, to send it again
        self.tries = 0  # times it was sent (timer "answer": send again, or give it up)
        self.partners: set[int] = set()  # a Sink may have several at once
        self.stations: set[int] = set()  # robots that answered as Generator or Sink
        self.came_from = -1  # who handed this robot its bucket
        self.radius = params.range  # timer "retry": a failed round is tried again

    def choose(self, view: SearchView) -> list[int]:
        """The robots to ask, best first (an empty list: carry it, or retry)."""
        raise NotImplementedError(f"{type(self).__name__} must implement choose()")

    # -- having a bucket ------------------------------------------------------------------

    async def on_timer(self, key: Hashable) -> None:
        """A failed round is retried (``"retry"``); an answer is overdue (``"answer"``)."""
        if key == "retry":
            await self._search()
        elif key == "answer" and self.asked >= 0 and self.question is not None:
            self._no_answer(self.question)

    def _no_answer(self, question: RequestPartner) -> None:
        """The robot asked has not answered ``question`` in time: ask again, or give it up."""
        if self.tries <= self.params.retries:
            self.resend(self.asked, question)
            self._await_answer()
        else:
            self.log.info(
                "robot %d did not answer %d requests: asking others", self.asked, self.tries
            )
            self._ask_next()

    def _await_answer(self) -> None:
        self.tries += 1
        self.wake_after(self.params.timeout, "answer")

    async def on_restart(self, error: Exception) -> None:
        """After a failure (with ``[run] restarts``): drop the round under way, search anew."""
        self.asked = -1
        if self.bucket >= 0 and not self.partners:  # from the timer, not from here
            self.wake_after(0.0, "retry")

    def _retry_later(self) -> None:
        # A timer, not a sleep: requests keep being answered meanwhile.
        self.wake_after(self.params.retry_interval, "retry")

    async def store_intra_msg(self, msg: Message) -> None:
        """From the Goal layer: a bucket to move; from below: a hand-over or a leg done."""
        match msg:
            case MoveBucket():
                self.bucket, self.sink, self.sink_at = msg.bucket, msg.to.sink, msg.to.at
                self.radius = self.params.range
                await self._search()
            case Moved():
                await self._search()
            case Abandoned(partner=partner, has_bucket=has_bucket):
                self.partners.discard(partner)
                if has_bucket:  # a giver whose partner went silent: find another
                    await self._search()
            case Exchanged(partner=partner, has_bucket=has_bucket):
                self.partners.discard(partner)
                # Hold the bucket from now on, not from the Goal layer's MoveBucket: a
                # partnership request arriving in between must be refused.
                self.bucket = msg.bucket if has_bucket else -1
                self.came_from = partner if has_bucket else -1
                self.send_up(msg)
            case _:
                self.unexpected(msg, "not a message the Strategy layer takes from its neighbours")

    async def _search(self) -> None:
        self.searching = True
        found = await self.request_layer(
            ACTION, RequestRobotsInRange(self.radius), reply=RobotsInRange
        )
        self.here = (found.x, found.y)
        candidates = tuple(
            Candidate(rid, (x, y))
            for rid, x, y in zip(found.ids, found.xs, found.ys, strict=True)
            if self._may_take(rid)
        )
        view = SearchView(
            self.robot_id,
            self.kind,
            self.here,
            self._carrying(found.speed),
            self.sink,
            self.sink_at,
            candidates,
            self.params,
        )
        chosen = self.choose(view)
        allowed = {candidate.robot for candidate in candidates}
        self.to_ask = list(dict.fromkeys(r for r in chosen if r in allowed))
        if len(self.to_ask) < len(chosen):
            self.log.warning("choose() returned robots that are not candidates: %s", chosen)
        self._ask_next()

    def _may_take(self, robot: int) -> bool:
        """Whether ``robot`` could take the bucket: not a known station, unless the sink.

        An immobile robot (a Generator) cannot hand over to a Sink: they cannot meet;
        and the bucket does not go back to the robot it came from.
        """
        if robot == self.sink:
            return self.params.mobile
        # Never straight back: two robots would pass a bucket to and fro forever.
        return robot not in self.stations and robot != self.came_from

    def _carrying(self, speed_now: float) -> SpeedProfile | None:
        return self.params.carrying(speed_now) if self.params.mobile else None

    def _ask_next(self) -> None:
        if self.to_ask:
            self.asked = self.to_ask.pop(0)
            request = RequestPartner(
                self.here[0],
                self.here[1],
                self.kind,
                bucket=self.bucket,
                to=Destination(self.sink, *self.sink_at),
                msg_type=MsgType.NEGOTIATION,
            )
            self.send(self.asked, request)
            self.asked_in = request.msg_id  # stamped by send()
            self.question = request
            self.tries = 0
            self._await_answer()
            return
        self.asked = -1
        if self.params.mobile:
            self._carry_a_step()
        else:
            # A Generator must find a partner: look farther next time (capped at the
            # world's diagonal, which covers everyone, or the interaction range).
            self.radius = min(self.radius * self.params.search_growth, self.params.farthest)
            self._retry_later()

    def _carry_a_step(self) -> None:
        gap = distance(self.here, self.sink_at)
        if gap <= _ARRIVED:
            # At the sink and nobody to ask (a strategy that skipped it): without a
            # pause this would search again at the same instant forever.
            self._retry_later()
            return
        self.searching = False
        step = min(self.params.search_step, gap)
        fraction = step / gap
        target = (
            self.here[0] + (self.sink_at[0] - self.here[0]) * fraction,
            self.here[1] + (self.sink_at[1] - self.here[1]) * fraction,
        )
        self.send_down(Carry(target[0], target[1]))

    # -- other robots' requests, and answers to ours -----------------------------------------

    async def handle_msg(self, msg: Message) -> None:
        """Answers partnership requests; takes the answers to this robot's own."""
        match msg:
            case RequestPartner(msg_type=MsgType.NEGOTIATION):
                if self.in_world((msg.x, msg.y), msg.to.at):
                    self._answer(msg)
                else:
                    self.unexpected(msg, "a position outside the world")
            case PartnerAnswer():
                self._answered(msg)
            case _:
                self.unexpected(msg, "the Strategy layer only takes RequestPartner and its answer")

    def _answered(self, msg: PartnerAnswer) -> None:
        """The answer to this robot's request: a partner, or the next robot to ask."""
        if msg.robot_id != self.asked or msg.corr_id != self.asked_in:
            self.late(msg, "not the answer awaited")
        elif msg.msg_type == MsgType.ACCEPT:
            self._partnered(msg.robot_id, giver=True, bucket=self.bucket, deal=self.asked_in)
        else:
            if msg.kind != Kind.TRANSPORTER:
                self.stations.add(msg.robot_id)
            self._ask_next()

    def _free(self, asker: Kind) -> bool:
        if self.kind is Kind.SINK:
            return asker == Kind.TRANSPORTER  # two immobile robots cannot meet
        return (
            self.kind is Kind.TRANSPORTER
            and self.bucket < 0
            and not self.partners
            and not self.searching
        )

    def _answer(self, msg: RequestPartner) -> None:
        if msg.kind != Kind.TRANSPORTER:
            self.stations.add(msg.robot_id)  # so this robot never asks it in turn
        if not self._free(msg.kind):
            self.reply(msg, PartnerAnswer(self.kind, msg_type=MsgType.DENY))
            return
        self.bucket, self.sink, self.sink_at = -1, msg.to.sink, msg.to.at
        self._partnered(msg.robot_id, giver=False, bucket=msg.bucket, deal=msg.msg_id)
        self.reply(msg, PartnerAnswer(self.kind))

    def _partnered(self, partner: int, *, giver: bool, bucket: int, deal: int) -> None:
        # Group Activity hears of the partnership before the partner does: its Meet
        # request can only arrive after this robot's answer.
        self.partners.add(partner)
        self.asked = -1
        self.searching = False
        self.send_down(
            Partnered(
                partner=partner,
                giver=giver,
                bucket=bucket,
                to=Destination(self.sink, *self.sink_at),
                deal=deal,
            )
        )
