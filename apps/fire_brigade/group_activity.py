"""The Group Activity layer (thesis Fig. 30): agreeing on a meeting point with the partner.

On ``"Partnered"`` from the Strategy layer, the giver sends ``Meet`` with its position,
kind and current speed. The partner works out where they will meet (both moving
toward each other at once; at the immobile one's position when one cannot move),
answers with that point, and both tell their Task layer (``"Meeting"``). A solo leg
(``"Carry"``) passes straight through to the Task layer. Completions from below
(``"Exchanged"``, ``"Moved"``) are passed up to the Strategy layer.
"""

from __future__ import annotations

from cas_async import ConstantSpeed, Message, MsgType, SpeedProfile

from .base import ACTION, BrigadeLayer, Params, Point
from .estimate import meeting_point
from .messages import ChangeStatus, Meet, RequestInfo

__all__ = ["GroupActivity"]


class GroupActivity(BrigadeLayer):
    """Coordinates each partnership's meeting point (a Sink may have several at once)."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.partnerships: dict[int, ChangeStatus] = {}  # partner -> the "Partnered" status

    async def _where(self) -> RequestInfo:
        where = await self.request_layer(ACTION, RequestInfo())
        assert isinstance(where, RequestInfo)
        return where

    def _profile(self, speed: float, *, carrying: bool) -> SpeedProfile | None:
        """How a robot moving at ``speed`` now will move (``None``: it cannot)."""
        if speed <= 0:
            return None
        return self.params.carrying(speed) if carrying else ConstantSpeed(speed)

    async def store_intra_msg(self, msg: Message) -> None:
        """From above: a partnership or a solo leg; from below: their completion."""
        if not isinstance(msg, ChangeStatus):
            self.unexpected(msg, "the Group Activity layer expects ChangeStatus")
        elif msg.status == "Partnered":
            self.partnerships[msg.partner] = msg
            if msg.has_bucket:  # the giver opens the coordination
                where = await self._where()
                self.send(
                    msg.partner,
                    Meet(
                        where.x,
                        where.y,
                        self.kind,
                        where.speed,
                        deal=msg.deal,
                        msg_type=MsgType.NEGOTIATION,
                    ),
                )
        elif msg.status == "Carry":
            self.send_down(msg)
        elif msg.status == "Exchanged":
            self.partnerships.pop(msg.partner, None)
            self.send_up(msg)
        elif msg.status == "Moved":
            self.send_up(msg)
        else:
            self.unexpected(msg, f"unknown status {msg.status!r}")

    async def handle_msg(self, msg: Message) -> None:
        """The partner's Meet: answer with the meeting point, or take the answer."""
        if not isinstance(msg, Meet):
            self.unexpected(msg, "the Group Activity layer only exchanges Meet")
            return
        partnership = self.partnerships.get(msg.robot_id)
        if partnership is not None and partnership.deal != msg.deal:
            partnership = None  # a message of an earlier partnership with that robot
        if msg.msg_type == MsgType.NEGOTIATION:
            if partnership is None or partnership.has_bucket:
                refusal = Meet(0.0, 0.0, self.kind, msg_type=MsgType.DENY)
                self.reply(msg, refusal)
                self.unexpected(msg, "not this robot's partner")
                return
            where = await self._where()
            point = meeting_point(
                (msg.x, msg.y),
                (where.x, where.y),
                self._profile(msg.speed, carrying=True),
                self._profile(where.speed, carrying=False),
            )
            self.reply(msg, Meet(point[0], point[1], self.kind, deal=msg.deal))
            self._meet_at(partnership, point)
        elif partnership is None or msg.msg_type == MsgType.DENY:
            # Cannot happen between robots running this app: partnerships are agreed first.
            raise RuntimeError(f"robot {self.robot_id}: robot {msg.robot_id} refused to meet")
        else:
            self._meet_at(partnership, (msg.x, msg.y))

    def _meet_at(self, partnership: ChangeStatus, point: Point) -> None:
        self.send_down(
            ChangeStatus(
                "Meeting",
                partner=partnership.partner,
                x=point[0],
                y=point[1],
                has_bucket=partnership.has_bucket,
                bucket=partnership.bucket,
                sink=partnership.sink,
                sink_x=partnership.sink_x,
                sink_y=partnership.sink_y,
                deal=partnership.deal,
            )
        )
