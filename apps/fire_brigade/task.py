"""The Task layer (thesis Fig. 31): getting to the meeting point and swapping the bucket.

It compares where the robot is with where it should be and asks the Action layer
to rotate (to face the target) or move, until the robot is there. Then it tells
the partner (``Meeting``, NEGOTIATION); the partner answers (ACCEPT) once it is
there too. When both are at the meeting point the giver's Action layer hands the
bucket over, and the giver sends ``Handover``; the receiver's Action layer then
takes it. Each side reports ``"Exchanged"`` up the stack. A solo leg (``"Carry"``)
is a move followed by ``"Moved"``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cas_async import Message, MsgType

from .base import BrigadeLayer, Params
from .messages import ChangeStatus, CompletionStatus, Handover, Meeting

__all__ = ["Task"]

_THERE = 1e-9
"""Distance (and heading difference, in radians) below which a target is reached."""


@dataclass(slots=True)
class _Meeting:
    """One partnership's progress at the meeting point."""

    plan: ChangeStatus
    arrived: bool = False
    partner_arrived: bool = False
    handed_over: bool = False  # the receiver got the giver's Handover
    swapped: bool = False


class Task(BrigadeLayer):
    """Plans the physical actions of a meeting, or of a solo leg, and evaluates each."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.meetings: dict[int, _Meeting] = {}  # partner -> progress
        self.x = self.y = self.heading = 0.0

    async def _act(self, command: ChangeStatus) -> CompletionStatus:
        done = await self.request_down(command)
        assert isinstance(done, CompletionStatus)
        self.x, self.y, self.heading = done.x, done.y, done.heading
        return done

    async def _go_to(self, x: float, y: float) -> None:
        """Rotate to face the target, then move; evaluate after each action (Fig. 31)."""
        await self._act(ChangeStatus("Where"))
        while math.hypot(x - self.x, y - self.y) > _THERE:
            facing = math.atan2(y - self.y, x - self.x)
            turn = math.remainder(facing - self.heading, math.tau)
            if abs(turn) > _THERE:
                await self._act(ChangeStatus("Rotate", x=x, y=y))
            else:
                await self._act(ChangeStatus("Move", x=x, y=y))

    async def store_intra_msg(self, msg: Message) -> None:
        """A meeting or a solo leg from above."""
        if not isinstance(msg, ChangeStatus):
            self.unexpected(msg, "the Task layer expects ChangeStatus")
        elif msg.status == "Meeting":
            meeting = self.meetings[msg.partner] = _Meeting(msg)
            if self.params.mobile:
                await self._go_to(msg.x, msg.y)
            meeting.arrived = True
            # "I am here", as a request the partner answers once it is there too.
            self.send(msg.partner, Meeting(msg.deal, msg_type=MsgType.NEGOTIATION))
            await self._progress(msg.partner)
        elif msg.status == "Carry":
            await self._go_to(msg.x, msg.y)
            moved = ChangeStatus("Moved", x=self.x, y=self.y, has_bucket=True, bucket=msg.bucket)
            self.send_up(moved)
        else:
            self.unexpected(msg, f"unknown status {msg.status!r}")

    async def handle_msg(self, msg: Message) -> None:
        """The partner's Meeting (it is there) or Handover (the bucket is ours)."""
        meeting = self.meetings.get(msg.robot_id)
        if not isinstance(msg, Meeting | Handover):
            self.unexpected(msg, "the Task layer only exchanges Meeting and Handover")
            return
        if meeting is None or msg.deal != meeting.plan.deal:
            # When both robots arrive at nearly the same time their Meeting messages
            # cross, and the second one comes after the swap, perhaps even during a new
            # partnership of the same two robots: it belongs to a finished deal.
            if isinstance(msg, Handover):
                self.unexpected(msg, f"no meeting with robot {msg.robot_id} for this deal")
            return
        if isinstance(msg, Meeting):
            meeting.partner_arrived = True
            if msg.msg_type == MsgType.NEGOTIATION and meeting.arrived:
                self.reply(msg, Meeting(meeting.plan.deal))
        elif not meeting.plan.has_bucket:
            meeting.partner_arrived = meeting.handed_over = True
        else:
            self.unexpected(msg, "a Handover to the giver")
            return
        await self._progress(msg.robot_id)

    async def _progress(self, partner: int) -> None:
        """Swap the bucket once both robots are there (the giver acts, the receiver follows)."""
        meeting = self.meetings[partner]
        if meeting.swapped or not (meeting.arrived and meeting.partner_arrived):
            return
        plan = meeting.plan
        swap = ChangeStatus(
            "SwapBucket", partner=partner, bucket=plan.bucket, has_bucket=plan.has_bucket
        )
        if plan.has_bucket:
            done = await self._act(swap)
            self.send(partner, Handover(plan.bucket, plan.deal))
        elif meeting.handed_over:
            done = await self._act(swap)
        else:
            return  # there, but the bucket is not ours yet
        meeting.swapped = True
        del self.meetings[partner]
        self.send_up(
            ChangeStatus(
                "Exchanged",
                partner=partner,
                x=self.x,
                y=self.y,
                has_bucket=done.has_bucket,  # a Sink disposes of what it receives
                bucket=plan.bucket,
                sink=plan.sink,
                sink_x=plan.sink_x,
                sink_y=plan.sink_y,
            )
        )
