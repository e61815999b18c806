"""The Task layer (thesis Fig. 31): getting to the meeting point and swapping the bucket.

It compares where the robot is with where it should be and asks the Action layer
to rotate (``Rotate``, to face the target) or move (``Move``), until the robot is
there. On ``MeetAt`` it then tells the partner (``Meeting``, NEGOTIATION); the
partner answers (ACCEPT) once it is there too. When both are at the meeting point
the giver's Action layer hands the bucket over (``Give``), and the giver sends
``Handover``; the receiver's Action layer then takes it (``Take``). Each side
reports ``Exchanged`` up the stack. A solo leg (``Carry``) is a move followed by
``Moved``.

Over a lossy network the hand-over must still be all or nothing. The receiver
holds out its hands to the giver (``HoldOut``) before it drives to the meeting
point, and the giver's hand-over succeeds only into held-out hands. At the point
each robot says "I am here" every ``timeout`` until it knows the partner is there
too. A robot that hears nothing from its partner for ``patience`` seconds gives
up (``Abandoned``): the giver still holds the bucket and looks for another
partner; the receiver withdraws its hands (``Withdraw``) and looks into them: if
the bucket is there, the hand-over happened and only its notice was lost; if not,
no hand-over can happen any more. Either way both robots agree with what
physically happened.
"""

from __future__ import annotations

import math
from collections.abc import Hashable
from dataclasses import dataclass

from cas_async import Message, MsgType, RequestTimeout

from .base import BrigadeLayer, Params
from .messages import (
    Abandoned,
    Carry,
    Command,
    CompletionStatus,
    Exchanged,
    Give,
    Handover,
    HoldOut,
    MeetAt,
    Meeting,
    Move,
    Moved,
    Rotate,
    Take,
    Where,
    Withdraw,
)

__all__ = ["Task"]

_THERE = 1e-9
"""Distance (and heading difference, in radians) below which a target is reached."""


@dataclass(slots=True)
class _Meeting:
    """One partnership's progress at the meeting point."""

    plan: MeetAt
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

    async def _act(self, command: Command) -> CompletionStatus:
        done = await self.request_down(command, reply=CompletionStatus)
        self.x, self.y, self.heading = done.x, done.y, done.heading
        return done

    async def _go_to(self, x: float, y: float) -> None:
        """Rotate to face the target, then move; evaluate after each action (Fig. 31)."""
        await self._act(Where())
        while math.hypot(x - self.x, y - self.y) > _THERE:
            facing = math.atan2(y - self.y, x - self.x)
            turn = math.remainder(facing - self.heading, math.tau)
            if abs(turn) > _THERE:
                await self._act(Rotate(x, y))
            else:
                await self._act(Move(x, y))

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
        waiting = not meeting.partner_arrived or not (meeting.plan.giver or meeting.handed_over)
        if waiting:
            self.send(partner, Meeting(meeting.plan.deal, msg_type=MsgType.NEGOTIATION))
        self.wake_after(self.params.timeout, ("call", partner, meeting.plan.deal))

    async def store_intra_msg(self, msg: Message) -> None:
        """A meeting or a solo leg from above."""
        match msg:
            case MeetAt():
                await self._meet(msg)
            case Carry(x=x, y=y):
                await self._go_to(x, y)
                self.send_up(Moved(self.x, self.y))
            case _:
                self.unexpected(msg, "the Task layer only takes MeetAt and Carry from above")

    async def _meet(self, plan: MeetAt) -> None:
        """Drives to the meeting point, and calls the partner from there."""
        partner = plan.partner
        if not plan.giver:  # hands out to the giver, and to nobody else
            await self._act(HoldOut(partner))
        meeting = self.meetings[partner] = _Meeting(plan, self.clock.now())
        if self.params.mobile:
            await self._go_to(plan.x, plan.y)
        meeting.arrived = True
        self._heard(partner, meeting, self.clock.now())
        self._call(partner, meeting)
        await self._progress(partner)

    async def handle_msg(self, msg: Message) -> None:
        """The partner's Meeting (it is there) or Handover (the bucket is ours)."""
        match msg:
            case Meeting() | Handover():
                await self._from_partner(msg)
            case _:
                self.unexpected(msg, "the Task layer only exchanges Meeting and Handover")

    async def _from_partner(self, msg: Meeting | Handover) -> None:
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
        elif not meeting.plan.giver:
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
        if plan.giver:
            # Over once the bucket leaves: it travels to the partner's hands (the network's
            # latency), and the partner's silence meanwhile does not end the meeting.
            del self.meetings[partner]
            done = await self._act(Give(plan.bucket, partner))
            if done.has_bucket:  # the partner withdrew its hands: it gave up on us
                self._abandoned(plan, done)
                return
            self._exchanged(plan, done)
            await self._notify(partner, plan)
        elif meeting.handed_over:
            del self.meetings[partner]
            self._exchanged(plan, await self._act(Take(plan.bucket, partner)))

    async def _notify(self, partner: int, plan: MeetAt) -> None:
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
        if plan.giver:  # the giver never handed over: it still holds the bucket
            self._abandoned(plan, await self._act(Where()))
            return
        withdrawn = await self._act(Withdraw(partner, plan.bucket))
        if withdrawn.has_bucket:  # handed over; only the notice was lost
            self._exchanged(plan, await self._act(Take(plan.bucket, partner)))
        else:
            self._abandoned(plan, withdrawn)

    def _exchanged(self, plan: MeetAt, done: CompletionStatus) -> None:
        """The meeting ended with the bucket in the receiver's hands: say so upwards."""
        self.send_up(
            Exchanged(
                partner=plan.partner,
                bucket=plan.bucket,
                has_bucket=done.has_bucket,  # a Sink disposes of what it receives
                x=self.x,
                y=self.y,
                to=plan.to,
            )
        )

    def _abandoned(self, plan: MeetAt, done: CompletionStatus) -> None:
        """The meeting ended without a hand-over: say so upwards."""
        self.send_up(Abandoned(plan.partner, has_bucket=done.has_bucket))
