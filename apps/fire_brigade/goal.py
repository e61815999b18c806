"""The Goal layer (thesis Fig. 28): decides whether the robot moves a bucket, and where to.

* A robot that holds a bucket and has no destination finds one: a Generator asks
  every robot where it is and what it is (``RequestInfo``, answered with
  ``RobotInfo``) and picks the nearest Sink. Sinks never move, so the answer is
  kept for the Generator's next buckets. Robots that do not answer within
  ``timeout`` are asked again, up to ``retries`` times; then the Sinks known so far
  are enough (and without one it keeps asking).
  With ``sink_search = "nearby"`` it asks only the robots within ``range`` of it,
  then within a radius ``search_growth`` times larger, and so on, until a Sink has
  answered (up to the whole world): in a swarm of thousands, asking everyone is a
  flood of answers per Generator. The Sink chosen is the same: once one Sink within
  a radius has answered, the nearest Sink is within that radius too.
  A Transporter that receives a bucket takes over the destination its giver chose.
* With a destination, it hands the responsibility down: ``MoveBucket``.
* When the layers below report a hand-over (``Exchanged``): a Transporter that
  received a bucket moves it on; one that gave it away goes idle; a Generator
  makes a new bucket and starts again; a Sink stays idle.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

from cas_async import Message, MsgType

from .base import ACTION, BrigadeLayer, Params, Point
from .estimate import distance
from .messages import (
    BucketMade,
    Destination,
    Exchanged,
    Kind,
    MakeBucket,
    MoveBucket,
    RequestInfo,
    RequestRobotsInRange,
    RobotInfo,
    RobotsInRange,
)

__all__ = ["Goal"]


class Goal(BrigadeLayer):
    """Top layer: the robot's goal, "move this bucket to that sink" or idle."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.bucket = -1  # the bucket held, -1 when none
        self.sink = -1  # the destination chosen for it
        self.sink_at: Point = (0.0, 0.0)
        self.here: Point = (0.0, 0.0)
        self.delegated = False  # MoveBucket sent down and not yet completed
        self.asking = False  # a RequestInfo round is under way
        self.rounds = 0  # RequestInfo rounds sent in this search (timer "answers": over)
        self.answers: dict[int, RobotInfo] = {}
        self.sinks: dict[int, Point] | None = None  # known once a round completed
        # "nearby": the robots within radius (nearest first) and those of them that
        # have not answered yet; "everyone" asks the peers.
        self.asked: Sequence[int] = params.peers
        self.waiting: set[int] = set()
        self.radius = params.range

    async def on_timer(self, key: Hashable) -> None:
        """The current RequestInfo round is over (``inner_process`` runs next)."""
        if key == "answers" and self.asking:
            await self._round_over()

    async def inner_process(self) -> None:
        """Starts what the state calls for: a destination search or a MoveBucket."""
        if self.kind is Kind.GENERATOR and self.bucket < 0 and not self.delegated:
            await self._make_bucket()
        if self.bucket < 0 or self.delegated:
            return
        if self.sink < 0:
            if self.sinks is None:
                await self._ask_everyone()
                return
            self._choose_sink(self.sinks)
        self.delegated = True
        self.send_down(MoveBucket(bucket=self.bucket, to=Destination(self.sink, *self.sink_at)))

    async def _make_bucket(self) -> None:
        # Making a bucket is physical: the robotic layer does it.
        made = await self.request_layer(ACTION, MakeBucket(), reply=BucketMade)
        self.bucket = made.bucket
        self.here = (made.x, made.y)

    async def _ask_everyone(self) -> None:
        if self.asking:
            return
        self.asking = True
        self.rounds = 0
        if self.params.sink_search == "nearby":
            self.radius = self.params.range
            await self._ask_nearby()
            return
        where = await self.request_layer(ACTION, RequestInfo(), reply=RobotInfo)
        self.here = (where.x, where.y)
        self._ask(self.params.peers)

    async def _ask_nearby(self) -> None:
        """Asks the robots within ``radius`` that have not answered yet."""
        found = await self.request_layer(
            ACTION, RequestRobotsInRange(self.radius), reply=RobotsInRange
        )
        self.here = (found.x, found.y)
        self.asked = tuple(found.ids)
        self.rounds = 0
        answers = self.answers
        self.waiting = {r for r in self.asked if r not in answers}
        if self.waiting:
            self._ask(tuple(r for r in self.asked if r in self.waiting))
        else:  # nobody new within this radius: look farther at once
            await self._widen()

    async def _widen(self) -> None:
        """No Sink within ``radius`` has answered: asks within a wider one (up to the world).

        Raises:
            RuntimeError: the radius covers the world, everyone answered, and no
                robot is a Sink.
        """
        farthest = self.params.farthest
        if self.radius < farthest:
            self.radius = min(self.radius * self.params.search_growth, farthest)
            await self._ask_nearby()
        elif self.waiting:  # as far as it goes: keep asking the silent ones
            self._ask(tuple(r for r in self.asked if r in self.waiting))
        else:
            raise RuntimeError(f"robot {self.robot_id}: no robot of the swarm is a sink")

    def _ask(self, robots: Sequence[int]) -> None:
        self.broadcast(RequestInfo(msg_type=MsgType.NEGOTIATION), robots=robots)
        self.rounds += 1
        self.wake_after(self.params.timeout, "answers")

    async def _round_over(self) -> None:
        """Asks again who has not answered; after ``retries`` rounds, a Sink known is enough.

        Looking nearby, a search that found no Sink after ``retries`` rounds looks farther.
        """
        if self.rounds > self.params.retries:
            if self._settle():
                return
            if self.params.sink_search == "nearby":
                await self._widen()
                return
        if self.params.sink_search == "nearby":
            self._ask(tuple(r for r in self.asked if r in self.waiting))
        else:
            self._ask(tuple(r for r in self.params.peers if r not in self.answers))

    def _settle(self) -> bool:
        """Keeps the Sinks among the answers, if any; whether the search is over."""
        sinks = {rid: (i.x, i.y) for rid, i in self.answers.items() if i.kind is Kind.SINK}
        if not sinks:
            return False
        self.asking = False
        self.sinks = sinks
        self.answers.clear()
        return True

    def _choose_sink(self, sinks: dict[int, Point]) -> None:
        self.sink, self.sink_at = min(
            sinks.items(), key=lambda item: (distance(self.here, item[1]), item[0])
        )

    async def handle_msg(self, msg: Message) -> None:
        """Answers RequestInfo queries; collects the answers to this robot's own."""
        match msg:
            case RequestInfo(msg_type=MsgType.NEGOTIATION):
                where = await self.request_layer(ACTION, RequestInfo(), reply=RobotInfo)
                self.reply(msg, RobotInfo(where.x, where.y, self.kind, where.speed))
            case RobotInfo():
                await self._answered(msg)
            case _:
                self.unexpected(msg, "the Goal layer only exchanges RequestInfo and RobotInfo")

    async def _answered(self, msg: RobotInfo) -> None:
        """Another robot answered this robot's RequestInfo."""
        if not self.asking:
            self.late(msg, "no RequestInfo round is under way")
            return
        if not self.in_world((msg.x, msg.y)):
            self.unexpected(msg, "a position outside the world")
            return
        self.answers[msg.robot_id] = msg
        if self.params.sink_search == "nearby":
            waiting = self.waiting
            if msg.robot_id in waiting:
                waiting.discard(msg.robot_id)
                if not waiting and not self._settle():
                    await self._widen()
        elif len(self.answers) == len(self.params.peers) and not self._settle():
            raise RuntimeError(f"robot {self.robot_id}: no robot of the swarm is a sink")

    async def store_intra_msg(self, msg: Message) -> None:
        """A hand-over happened below: take the new state."""
        match msg:
            case Exchanged():
                self.delegated = False
                self.here = (msg.x, msg.y)
                if msg.has_bucket and self.kind is not Kind.SINK:
                    self.bucket = msg.bucket
                    self.sink, self.sink_at = msg.to.sink, msg.to.at
                else:
                    self.bucket = self.sink = -1
            case _:
                self.unexpected(msg, "the Goal layer only expects Exchanged from below")
