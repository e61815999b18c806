"""The Action layer (thesis Fig. 32): the robotic layer, executing what the Task layer asks.

It is the only layer that touches the robot, through its
:class:`~cas_async.Middleware` (motion, perception) and :class:`~cas_async.Hands`
(buckets): in simulation the kinematics and the Environment, on hardware the
drivers, without any other layer changing. Every command is an
internal request (a NEGOTIATION) answered when the action is over, with the
robot's pose (``CompletionStatus``). It also answers the upper layers' sensing
queries (``RequestInfo``, ``RequestRobotsInRange``).

Fatigue lives here: taking a bucket switches the motion to a decelerating speed
profile, handing it over resets it to full speed.

Hands: a receiver holds them out to its giver (``"Accept"``) and withdraws them
once it has the bucket or gives up (``"Withdraw"``); a hand-over into hands not
held out fails, and the giver keeps the bucket (see the Task layer).
"""

from __future__ import annotations

import math

from cas_async import Hands, Message, Middleware, SimulationError

from .base import BrigadeLayer, Params
from .messages import ChangeStatus, CompletionStatus, Kind, RequestInfo, RequestRobotsInRange

__all__ = ["Action"]


class Action(BrigadeLayer):
    """Executes moves, rotations and bucket swaps on the robot's middleware."""

    def __init__(self, params: Params, middleware: Middleware, hands: Hands) -> None:
        super().__init__(params)
        self.middleware = middleware
        self.hands = hands

    def _speed(self) -> float:
        if not self.params.mobile:
            return 0.0
        return self.middleware.speed_profile.speed_at(0.0)

    async def _done(self, action: str, bucket: int = -1) -> CompletionStatus:
        """The report of ``action``: the pose, and whether ``bucket`` is held now.

        Without a ``bucket``, whether the robot holds any. (A Sink may be handed
        several buckets at once: the report is about the one this action was for.)
        """
        pose = self.middleware.pose()
        held = await self.hands.items()
        if bucket < 0 and held:
            bucket = held[0]
        return CompletionStatus(
            action,
            x=pose.x,
            y=pose.y,
            heading=pose.heading,
            has_bucket=bucket in held,
            bucket=bucket,
        )

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """Performs the command or answers the query; see the module docs."""
        if isinstance(msg, RequestInfo):
            pose = self.middleware.pose()
            return RequestInfo(pose.x, pose.y, self.kind, self._speed())
        if isinstance(msg, RequestRobotsInRange):
            return await self._robots_in_range(msg.radius)
        if not isinstance(msg, ChangeStatus):
            self.unexpected(msg, "the Action layer only executes ChangeStatus commands")
            return None
        return await self._execute(msg)

    async def _robots_in_range(self, radius: float) -> RequestRobotsInRange:
        found = await self.middleware.robots_within(radius)
        pose = self.middleware.pose()
        return RequestRobotsInRange(
            radius,
            ids=found.ids.tolist(),
            xs=found.xy[:, 0].tolist(),
            ys=found.xy[:, 1].tolist(),
            x=pose.x,
            y=pose.y,
            speed=self._speed(),
        )

    async def _execute(self, command: ChangeStatus) -> CompletionStatus | None:
        status = command.status
        if status == "Where":
            return await self._done(status)
        if status == "Rotate":
            here = self.middleware.pose()
            await self.middleware.rotate_to(math.atan2(command.y - here.y, command.x - here.x))
            return await self._done(status)
        if status == "Move":
            await self.middleware.move_to(command.x, command.y)
            return await self._done(status)
        if status == "Accept":
            await self.hands.accept_from(command.partner)
            return await self._done(status)
        if status == "Withdraw":
            await self.hands.refuse_from(command.partner)
            return await self._done(status, command.bucket)
        if status == "MakeBucket":
            return await self._done(status, await self.hands.create_item())
        if status == "SwapBucket":
            if command.has_bucket:
                return await self._give(command.bucket, command.partner)
            return await self._take(command.bucket, command.partner)
        self.unexpected(command, f"unknown command {status!r}")
        return None

    async def _give(self, bucket: int, partner: int) -> CompletionStatus:
        await self.clock.sleep(self.params.handover_time)
        try:
            await self.hands.hand_over(bucket, partner)  # the one atomic moment of the exchange
        except SimulationError as refused:  # the partner withdrew its hands: no exchange
            self.log.info("hand-over refused: %s", refused)
            return await self._done("SwapBucket", bucket)
        if self.params.mobile:
            self.middleware.speed_profile = self.params.empty()
        return await self._done("SwapBucket", bucket)

    async def _take(self, bucket: int, giver: int) -> CompletionStatus:
        held = await self.hands.items()
        if bucket not in held:
            raise RuntimeError(
                f"robot {self.robot_id}: robot {giver} reported handing over bucket {bucket}, "
                f"but this robot holds {list(held)}"
            )
        await self.hands.refuse_from(giver)  # hands back in: nothing more from this giver
        if self.kind is Kind.SINK:
            await self.hands.retire_item(bucket)
        elif self.params.mobile:
            self.middleware.speed_profile = self.params.carrying()
        return await self._done("SwapBucket", bucket)
