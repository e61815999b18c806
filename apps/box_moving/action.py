"""The Action layer (thesis §4.4: PickUp, Move, Scan): the only layer that touches the robot.

It drives the robot through its :class:`~cas_async.Middleware` and lifts
objects with its :class:`~apps.box_moving.gripper.Gripper`: in simulation the
kinematics and the Floor, on hardware the drivers, without any other layer
changing.

* ``Scan`` (from Decision-Making): looks at the objects free to take and sends
  them up as a ``ScanResult``.
* ``Claim`` / ``Unclaim``: marks the selected object as this robot's, or not.
* ``CarryOut`` (from Coordination): PickUp: drives to the agreed side of the
  object at its empty speed, lifts it (``lift_time``), and switches to the
  agreed carrying speed. Alone, it then moves (Move) to where the object's
  centre is at its drop spot and puts it down (``put_down_time``). In a joint
  carry it turns to face the drop spot (a leg then starts without turning)
  and reports ``Ready`` for leg 0 to Coordination.
* ``Go``: at the agreed instant, one leg: the object's centre to the leg's end
  (this robot to that point plus its side's offset); then ``Ready`` for the next.
* ``Release``: at the agreed instant, the put-down.

Every carry ends with ``CarryDone`` up the stack, and with ``MovedCount`` (the
objects the robot sees in the drop zone) whenever that changed, as after
every scan. ``Where`` and ``Locate`` are answered at once (when the layer is
not in the middle of a motion: a move is awaited inside the hook).
"""

from __future__ import annotations

import math

from cas_async import ConstantSpeed, Message, Middleware

from .base import DECISION_MAKING, Params, Shared
from .geometry import Point, side_offset, side_point
from .gripper import Gripper
from .messages import (
    CarryDone,
    CarryOut,
    Claim,
    Go,
    Locate,
    Located,
    MovedCount,
    Position,
    Ready,
    Release,
    Role,
    Scan,
    ScanResult,
    Sighting,
    Unclaim,
    Where,
)

__all__ = ["Action"]


class Action(Shared):
    """Executes scans, lifts, moves and put-downs on the robot's middleware and gripper.

    Args:
        params: the robot's constants.
        middleware: the robot's motion and perception.
        gripper: the robot's arms and object sensors.
    """

    def __init__(self, params: Params, middleware: Middleware, gripper: Gripper) -> None:
        super().__init__(params)
        self.middleware = middleware
        self.gripper = gripper
        self.carry: CarryOut | None = None  # the carry under way

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """Answers ``Where`` and ``Locate``."""
        match msg:
            case Where():
                pose = self.middleware.pose()
                return Position(pose.x, pose.y, pose.heading)
            case Locate():
                found = await self.middleware.robots_within(math.inf)
                pose = self.middleware.pose()
                return Located(
                    ids=found.ids.tolist(),
                    xs=found.xy[:, 0].tolist(),
                    ys=found.xy[:, 1].tolist(),
                    x=pose.x,
                    y=pose.y,
                )
        self.unexpected(msg, "not a query of the Action layer")
        return None

    async def store_intra_msg(self, msg: Message) -> None:
        """Scans, marks, and carries out what the layers above decided."""
        match msg:
            case Scan():
                await self._scan()
            case Claim(obj=obj):
                await self.gripper.claim(obj)
            case Unclaim(obj=obj):
                await self.gripper.unclaim(obj)
            case CarryOut():
                await self._pick_up(msg)
            case Go():
                await self._leg(msg)
            case Release():
                await self._release(msg)
            case _:
                self.unexpected(msg, "not a command of the Action layer")

    async def handle_msg(self, msg: Message) -> None:
        """Logs a message from another robot: the robotic layer talks to none."""
        self.unexpected(msg, "the Action layer talks to no other robot")

    # -- Scan ------------------------------------------------------------------------------

    async def _scan(self) -> None:
        boxes = await self.gripper.scan()
        moved = await self.gripper.moved()
        pose = self.middleware.pose()
        seen = [
            Sighting(box.obj, box.x, box.y, box.weight, box.size, box.drop_x, box.drop_y)
            for box in boxes
        ]
        self.send_to_layer(DECISION_MAKING, ScanResult(pose.x, pose.y, seen, moved))
        self._report(moved)

    def _report(self, moved: int) -> None:
        """Tells the layers above how many objects are moved, when that is news."""
        if self.learn_moved(moved):
            self.send_up(MovedCount(moved))

    # -- PickUp and Move -------------------------------------------------------------------

    async def _pick_up(self, order: CarryOut) -> None:
        if self.carry is not None:
            raise RuntimeError(
                f"robot {self.robot_id}: told to carry object {order.object.obj} while "
                f"carrying object {self.carry.object.obj}"
            )
        self.carry = order
        box = order.object
        self.middleware.speed_profile = ConstantSpeed(self.params.speed)
        await self.middleware.move_to(*side_point((box.x, box.y), order.side, box.size))
        await self.clock.sleep(self.params.lift_time)
        await self.gripper.lift(box.obj, order.side, order.partner or None)
        self.middleware.speed_profile = ConstantSpeed(order.speed)
        if order.role is Role.SOLO:
            await self._move((box.drop_x, box.drop_y))
            await self._put_down()
            return
        # Turning now, while the pair does not move, means no leg starts with a turn:
        # both robots then set off, and arrive, at the same instants.
        await self.middleware.rotate_to(math.atan2(box.drop_y - box.y, box.drop_x - box.x))
        self.send_up(Ready(box.obj, 0))

    async def _move(self, centre: Point) -> None:
        """Moves so that the carried object's centre reaches ``centre``."""
        carry = self._carrying()
        dx, dy = side_offset(carry.side, carry.object.size)
        await self.middleware.move_to(centre[0] + dx, centre[1] + dy)

    async def _leg(self, go: Go) -> None:
        carry = self._carrying()
        if go.obj != carry.object.obj:
            self.unexpected(go, f"this robot carries object {carry.object.obj}")
            return
        await self.clock.sleep_until(go.at)
        await self._move((go.x, go.y))
        self.send_up(Ready(go.obj, go.leg + 1))

    async def _release(self, release: Release) -> None:
        carry = self._carrying()
        if release.obj != carry.object.obj:
            self.unexpected(release, f"this robot carries object {carry.object.obj}")
            return
        await self.clock.sleep_until(release.at)
        await self._put_down()

    async def _put_down(self) -> None:
        carry = self._carrying()
        await self.clock.sleep(self.params.put_down_time)
        await self.gripper.put_down(carry.object.obj)
        self.carry = None
        self.middleware.speed_profile = ConstantSpeed(self.params.speed)
        self.send_up(CarryDone(carry.object.obj))
        self._report(await self.gripper.moved())

    def _carrying(self) -> CarryOut:
        if self.carry is None:
            raise RuntimeError(f"robot {self.robot_id}: told to move an object it does not carry")
        return self.carry
