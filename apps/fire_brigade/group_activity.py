"""The Group Activity layer (thesis Fig. 30): agreeing on a meeting point with the partner.

On ``Partnered`` from the Strategy layer, the giver sends ``Meet`` with its position,
kind and current speed. The partner works out where they will meet (both moving
toward each other at once; at the immobile one's position when one cannot move),
answers with that point (``MeetingPoint``), and both tell their Task layer
(``MeetAt``). A solo leg (``Carry``) passes straight through to the Task layer.
Completions from below (``Exchanged``, ``Moved``, ``Abandoned``) are passed up to
the Strategy layer.

A partner may go silent (or the network may lose every copy of a message): the
giver asks ``Meet`` again up to ``retries`` times and gives up after that; the
receiver gives up when no ``Meet`` came within twice that time. Giving up is
reported upwards as ``Abandoned``; a ``Meet`` for a partnership given up is
refused (DENY), so the giver gives up too.
"""

from __future__ import annotations

from collections.abc import Hashable

from cas_async import ConstantSpeed, Message, MsgType, RequestTimeout, SpeedProfile

from .base import ACTION, BrigadeLayer, Params, Point
from .estimate import meeting_point
from .messages import (
    Abandoned,
    Carry,
    Exchanged,
    Meet,
    MeetAt,
    MeetingPoint,
    Moved,
    Partnered,
    RequestInfo,
    RobotInfo,
)

__all__ = ["GroupActivity"]


class GroupActivity(BrigadeLayer):
    """Coordinates each partnership's meeting point (a Sink may have several at once)."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        # partner -> the partnership; a receiver arms the timer ("meet", partner) for
        # when the partner's Meet is overdue.
        self.partnerships: dict[int, Partnered] = {}

    async def _where(self) -> RobotInfo:
        return await self.request_layer(ACTION, RequestInfo(), reply=RobotInfo)

    def _profile(self, speed: float, *, carrying: bool) -> SpeedProfile | None:
        """How a robot moving at ``speed`` now will move (``None``: it cannot)."""
        if speed <= 0:
            return None
        return self.params.carrying(speed) if carrying else ConstantSpeed(speed)

    async def on_timer(self, key: Hashable) -> None:
        """A receiver whose giver never sent ``Meet`` gives the partnership up."""
        match key:
            case ("meet", int(partner)):
                partnership = self.partnerships.pop(partner, None)
                if partnership is not None:
                    self.log.info("robot %d never sent Meet: partnership abandoned", partner)
                    self._abandoned(partnership)

    def _abandoned(self, partnership: Partnered) -> None:
        self.send_up(Abandoned(partnership.partner, has_bucket=partnership.giver))

    async def store_intra_msg(self, msg: Message) -> None:
        """From above: a partnership or a solo leg; from below: their completion."""
        match msg:
            case Partnered():
                self.partnerships[msg.partner] = msg
                if msg.giver:  # the giver opens the coordination
                    await self._open_meeting(msg)
                else:
                    self.wake_after(2 * self.params.give_up_after, ("meet", msg.partner))
            case Carry():
                self.send_down(msg)
            case Exchanged(partner=partner) | Abandoned(partner=partner):
                self.partnerships.pop(partner, None)
                self.send_up(msg)
            case Moved():
                self.send_up(msg)
            case _:
                self.unexpected(msg, "not a message Group Activity takes from its neighbours")

    async def _open_meeting(self, partnership: Partnered) -> None:
        where = await self._where()
        ask = Meet(where.x, where.y, self.kind, where.speed, deal=partnership.deal)
        try:
            answer: MeetingPoint | None = await self.request(
                partnership.partner,
                ask,
                reply=MeetingPoint,
                timeout=self.params.timeout,
                retries=self.params.retries,
            )
        except RequestTimeout:
            answer = None
        if self.partnerships.get(partnership.partner) is not partnership:
            return  # cannot happen: a giver has one partnership at a time
        if (
            answer is None
            or answer.msg_type != MsgType.ACCEPT
            or not self.in_world((answer.x, answer.y))
        ):
            self.log.info("robot %d did not agree to meet", partnership.partner)
            del self.partnerships[partnership.partner]
            self._abandoned(partnership)
            return
        self._meet_at(partnership, (answer.x, answer.y))

    async def handle_msg(self, msg: Message) -> None:
        """The giver's Meet: answer with the meeting point (or refuse an unknown partnership)."""
        match msg:
            case Meet(msg_type=MsgType.NEGOTIATION):
                await self._meet(msg)
            case _:
                self.unexpected(msg, "the Group Activity layer only takes Meet requests")

    async def _meet(self, msg: Meet) -> None:
        refusal = MeetingPoint(msg.x, msg.y, msg.deal, msg_type=MsgType.DENY)
        partnership = self.partnerships.get(msg.robot_id)
        if partnership is not None and partnership.deal != msg.deal:
            partnership = None  # a message of an earlier partnership with that robot
        if partnership is None or partnership.giver:
            self.reply(msg, refusal)
            self.late(msg, "not (or no longer) this robot's partner")
            return
        if not self.in_world((msg.x, msg.y)):
            self.reply(msg, refusal)
            self.unexpected(msg, "a position outside the world")
            return
        self.cancel_wake(("meet", msg.robot_id))
        where = await self._where()
        point = meeting_point(
            (msg.x, msg.y),
            (where.x, where.y),
            self._profile(msg.speed, carrying=True),
            self._profile(where.speed, carrying=False),
        )
        self.reply(msg, MeetingPoint(point[0], point[1], msg.deal))
        self._meet_at(partnership, point)

    def _meet_at(self, partnership: Partnered, point: Point) -> None:
        self.send_down(
            MeetAt(
                partner=partnership.partner,
                x=point[0],
                y=point[1],
                giver=partnership.giver,
                bucket=partnership.bucket,
                to=partnership.to,
                deal=partnership.deal,
            )
        )
