"""The Task layer (thesis Fig. 31): getting to the meeting point and swapping the bucket.

It compares where the robot is with where it should be and asks the Action layer
to rotate (to face the target) or move, until the robot is there. Then it tells
the partner (``Meeting``, NEGOTIATION); the partner answers (ACCEPT) once it is
there too. When both are at the meeting point the giver's Action layer hands the
bucket over, and the giver sends ``Handover``; the receiver's Action layer then
takes it. Each side reports ``"Exchanged"`` up the stack. A solo leg (``"Carry"``)
is a move followed by ``"Moved"``.

Over a lossy network the hand-over must still be all or nothing. The receiver
holds out its hands to the giver (``"Accept"``) before it drives to the meeting
point, and the giver's hand-over succeeds only into held-out hands. At the point
each robot says "I am here" every ``timeout`` until it knows the partner is there
too. A robot that hears nothing from its partner for ``patience`` seconds gives
up: the giver still holds the bucket and looks for another partner; the receiver
withdraws its hands (``"Withdraw"``) and looks into them: if the bucket is there,
the hand-over happened and only its notice was lost; if not, no hand-over can
happen any more. Either way both robots agree with what physically happened.
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from dataclasses import dataclass

from cas_async import Message, MsgType, RequestTimeout

from .base import BrigadeLayer, Params
from .messages import ChangeStatus, CompletionStatus, Handover, Meeting

__all__ = ["Task"]

_THERE = 1e-9
"""Distance (and heading difference, in radians) below which a target is reached."""


@dataclass(slots=True)
class _Meeting:
    """One partnership's progress at the meeting point."""

    plan: ChangeStatus
    heard: float  # when the partner was last heard of (or the robot arrived)
    arrived: bool = False
    partner_arrived: bool = False
    handed_over: bool = False  # the receiver got the giver's Handover


class Task(BrigadeLayer):
    """Plans the physical actions of a meeting, or of a solo leg, and evaluates each."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.meetings: dict[int, _Meeting] = {}  # partner -> progress
        self.x = self.y = self.heading = 0.0

    async def _act(self, command: ChangeStatus) -> CompletionStatus:
        done = await self.request_down(command, reply=CompletionStatus)
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

    async def on_timer(self, key: Hashable) -> None:
        """At a meeting point: call the partner again, or give a silent partner up.

        Per meeting, ``("call", partner, deal)`` goes off every ``timeout`` and
        ``("patience", partner, deal)`` ``patience`` seconds after the partner was
        last heard of; the deal in the key keeps a timer of an earlier meeting with
        the same partner from acting on a later one.
        """
        match key:
            case (what, int(partner), int(deal)):
                meeting = self.meetings.get(partner)
                if meeting is None or meeting.plan.deal != deal or not meeting.arrived:
                    return
                if what == "patience":
                    await self._give_up(partner, meeting)
                elif what == "call":
                    self._call(partner, meeting)

    def _heard(self, partner: int, meeting: _Meeting, at: float) -> None:
        """The partner was heard of (or this robot arrived) at ``at``: patience starts again.

        Patience only runs at the meeting point: before arriving, it is noted only.
        """
        meeting.heard = max(meeting.heard, at)
        if meeting.arrived:
            deal = meeting.plan.deal
            self.wake_at(meeting.heard + self.params.patience, ("patience", partner, deal))

    def _call(self, partner: int, meeting: _Meeting) -> None:
        """Says "I am here" until the partner is known there (the receiver: and handed over)."""
        waiting = not meeting.partner_arrived or not (
            meeting.plan.has_bucket or meeting.handed_over
        )
        if waiting:
            self.send(partner, Meeting(meeting.plan.deal, msg_type=MsgType.NEGOTIATION))
        self.wake_after(self.params.timeout, ("call", partner, meeting.plan.deal))

    async def store_intra_msg(self, msg: Message) -> None:
        """A meeting or a solo leg from above."""
        if not isinstance(msg, ChangeStatus):
            self.unexpected(msg, "the Task layer expects ChangeStatus")
        elif msg.status == "Meeting":
            if not msg.has_bucket:  # hands out to the giver, and to nobody else
                await self._act(ChangeStatus("Accept", partner=msg.partner))
            meeting = self.meetings[msg.partner] = _Meeting(msg, self.clock.now())
            if self.params.mobile:
                await self._go_to(msg.x, msg.y)
            meeting.arrived = True
            self._heard(msg.partner, meeting, self.clock.now())
            self._call(msg.partner, meeting)
            await self._progress(msg.partner)
        elif msg.status == "Carry":
            await self._go_to(msg.x, msg.y)
            moved = ChangeStatus("Moved", x=self.x, y=self.y, has_bucket=True, bucket=msg.bucket)
            self.send_up(moved)
        else:
            self.unexpected(msg, f"unknown status {msg.status!r}")

    async def handle_msg(self, msg: Message) -> None:
        """The partner's Meeting (it is there) or Handover (the bucket is ours)."""
        if not isinstance(msg, Meeting | Handover):
            self.unexpected(msg, "the Task layer only exchanges Meeting and Handover")
            return
        if isinstance(msg, Handover) and msg.msg_type == MsgType.NEGOTIATION:
            # Sent only once the bucket is in this robot's hands: always true, and the
            # giver stops asking once it hears so.
            self.reply(msg, Handover(msg.bucket, msg.deal))
        meeting = self.meetings.get(msg.robot_id)
        if meeting is None or msg.deal != meeting.plan.deal:
            # Calls cross: the partner's last "I am here" may come after the swap, or
            # after this robot gave up, even during a new partnership of the two.
            self.late(msg, f"no meeting with robot {msg.robot_id} for this deal")
            return
        self._heard(msg.robot_id, meeting, self.clock.now())
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
        meeting = self.meetings.get(partner)
        if meeting is None or not (meeting.arrived and meeting.partner_arrived):
            return
        plan = meeting.plan
        swap = ChangeStatus(
            "SwapBucket", partner=partner, bucket=plan.bucket, has_bucket=plan.has_bucket
        )
        if plan.has_bucket:
            done = await self._act(swap)
            if done.has_bucket:  # the partner withdrew its hands: it gave up on us
                del self.meetings[partner]
                self._report("Abandoned", plan, done)
                return
            del self.meetings[partner]
            self._report("Exchanged", plan, done)
            await self._notify(partner, plan)
        elif meeting.handed_over:
            del self.meetings[partner]
            self._report("Exchanged", plan, await self._act(swap))

    async def _notify(self, partner: int, plan: ChangeStatus) -> None:
        """Tells the receiver its hands hold the bucket (it would find out by itself anyway)."""
        try:
            await self.request(
                partner,
                Handover(plan.bucket, plan.deal),
                timeout=self.params.timeout,
                retries=self.params.retries,
            )
        except RequestTimeout:
            self.log.info("robot %d never confirmed the hand-over", partner)

    async def _give_up(self, partner: int, meeting: _Meeting) -> None:
        """The partner stayed silent for ``patience`` seconds: end the meeting as it stands."""
        del self.meetings[partner]
        plan = meeting.plan
        self.log.info("robot %d silent for %g s: meeting given up", partner, self.params.patience)
        if plan.has_bucket:  # the giver never handed over: it still holds the bucket
            self._report("Abandoned", plan, await self._act(ChangeStatus("Where")))
            return
        withdrawn = await self._act(ChangeStatus("Withdraw", partner=partner, bucket=plan.bucket))
        if withdrawn.has_bucket:  # handed over; only the notice was lost
            swap = ChangeStatus("SwapBucket", partner=partner, bucket=plan.bucket)
            self._report("Exchanged", plan, await self._act(swap))
        else:
            self._report("Abandoned", plan, withdrawn)

    def _report(self, status: str, plan: ChangeStatus, done: CompletionStatus) -> None:
        self.send_up(
            ChangeStatus(
                status,
                partner=plan.partner,
                x=self.x,
                y=self.y,
                has_bucket=done.has_bucket,  # a Sink disposes of what it receives
                bucket=plan.bucket,
                sink=plan.sink,
                sink_x=plan.sink_x,
                sink_y=plan.sink_y,
                deal=plan.deal,
            )
        )
