"""The Action layer (thesis Fig. 32): the robotic layer, executing what the Task layer asks.

It is the only layer that touches the robot, through its
:class:`~cas_async.Middleware` (motion, perception) and :class:`~cas_async.Hands`
(buckets): in simulation the kinematics and the Environment, on hardware the
drivers, without any other layer changing. Every command is an internal request
(a NEGOTIATION) answered when the action is over: the Task layer's commands
(``Where``, ``Rotate``, ``Move``, ``HoldOut``, ``Withdraw``, ``Give``, ``Take``) with
the robot's pose (``CompletionStatus``), the Goal layer's ``MakeBucket`` with the
new bucket (``BucketMade``). It also answers the upper layers' sensing queries
(``RequestInfo`` with ``RobotInfo``, ``RequestRobotsInRange`` with ``RobotsInRange``).

Fatigue lives here: taking a bucket switches the motion to a decelerating speed
profile, handing it over resets it to full speed.

Hands: a receiver holds them out to its giver (``HoldOut``) and withdraws them
once it has the bucket or gives up (``Withdraw``); a hand-over into hands not
held out fails, and the giver keeps the bucket (see the Task layer).
"""

from __future__ import annotations

import math

from cas_async import Hands, Message, Middleware, SimulationError

from .base import BrigadeLayer, Params
from .messages import (
    BucketMade,
    CompletionStatus,
    Give,
    HoldOut,
    Kind,
    MakeBucket,
    Move,
    RequestInfo,
    RequestRobotsInRange,
    RobotInfo,
    RobotsInRange,
    Rotate,
    Take,
    Where,
    Withdraw,
)

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

    async def _done(self, bucket: int | None = None) -> CompletionStatus:
        """The report of an action: the pose, and whether ``bucket`` is held now.

        Without a ``bucket``, whether the robot holds any. (A Sink may be handed
        several buckets at once: the report is about the one this action was for.)
        """
        pose = self.middleware.pose()
        held = await self.hands.items()
        return CompletionStatus(
            x=pose.x,
            y=pose.y,
            heading=pose.heading,
            has_bucket=bool(held) if bucket is None else bucket in held,
        )

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """Performs the command or answers the query; see the module docs."""
        match msg:
            case RequestInfo():
                pose = self.middleware.pose()
                return RobotInfo(pose.x, pose.y, self.kind, self._speed())
            case RequestRobotsInRange(radius=radius):
                return await self._robots_in_range(radius)
            case MakeBucket():
                bucket = await self.hands.create_item()
                pose = self.middleware.pose()
                return BucketMade(bucket, pose.x, pose.y)
            case Where():
                return await self._done()
            case Rotate(x=x, y=y):
                here = self.middleware.pose()
                await self.middleware.rotate_to(math.atan2(y - here.y, x - here.x))
                return await self._done()
            case Move(x=x, y=y):
                await self.middleware.move_to(x, y)
                return await self._done()
            case HoldOut(partner=partner):
                await self.hands.accept_from(partner)
                return await self._done()
            case Withdraw(partner=partner, bucket=bucket):
                await self.hands.refuse_from(partner)
                return await self._done(bucket)
            case Give(bucket=bucket, partner=partner):
                return await self._give(bucket, partner)
            case Take(bucket=bucket, partner=partner):
                return await self._take(bucket, partner)
        self.unexpected(msg, "not a command or query of the Action layer")
        return None

    async def store_intra_msg(self, msg: Message) -> None:
        """Logs what is not a request: the Action layer only answers them."""
        self.unexpected(msg, "the Action layer only answers requests")

    async def handle_msg(self, msg: Message) -> None:
        """Logs a message from another robot: the robotic layer talks to none."""
        self.unexpected(msg, "the Action layer talks to no other robot")

    async def _robots_in_range(self, radius: float) -> RobotsInRange:
        found = await self.middleware.robots_within(radius)
        pose = self.middleware.pose()
        return RobotsInRange(
            ids=found.ids.tolist(),
            xs=found.xy[:, 0].tolist(),
            ys=found.xy[:, 1].tolist(),
            x=pose.x,
            y=pose.y,
            speed=self._speed(),
        )

    async def _give(self, bucket: int, partner: int) -> CompletionStatus:
        await self.clock.sleep(self.params.handover_time)
        try:
            await self.hands.hand_over(bucket, partner)  # the one atomic moment of the exchange
        except SimulationError as refused:  # the partner withdrew its hands: no exchange
            self.log.info("hand-over refused: %s", refused)
            return await self._done(bucket)
        if self.params.mobile:
            self.middleware.speed_profile = self.params.empty()
        return await self._done(bucket)

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
        return await self._done(bucket)
