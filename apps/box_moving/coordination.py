"""The Coordination layer (thesis §4.4: AgreeOnBalancing, InformAction).

It turns the Task layer's ``Assignment`` into the Action layer's ``CarryOut``:

* alone: the side nearest the robot, at the robot's carrying speed for the weight;
* in a joint carry, the two robots agree on balancing (AgreeOnBalancing): the
  leader sends its position and carrying speed (``Balance``); the helper picks
  the sides with the layer's rule (:meth:`Coordination.choose_sides`) and the
  common speed, the slower of the two, and answers ``Balanced``. Each then
  informs its Action layer (InformAction).

During a joint carry it keeps the pair in step. The leader's Coordination
splits the way to the drop spot into legs of at most ``leg_length``; when both
robots are ``Ready`` for a leg (its own Action layer tells it; the helper's
Coordination forwards the helper's), it fixes the instant the leg starts,
``sync_margin`` seconds ahead, and sends ``Go`` to both Action layers (to the
helper's through the helper's Coordination). After the last leg, the same
for the put-down (``Release``). Both robots therefore start every leg, and the
put-down, at the same simulated instant.

Completions from below (``CarryDone``, ``MovedCount``) go up to the Task layer.

The default rule: each robot takes the side nearest where it stands. When
their nearest sides are not opposite (both robots come from the same
direction, say), the pair takes the two opposite sides that get both robots
there soonest: the assignment whose longer walk is shortest (then the shorter
walk; then west, east, south, north for the lower id). Subclass
and override :meth:`~Coordination.choose_sides` for another rule (see
:mod:`.coordination_fixed`); name it in a scenario's ``[layers]`` table.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from cas_async import Message, MsgType

from .base import BoxLayer, Params
from .geometry import Point, distance, legs, nearest_side, side_point
from .messages import (
    Assignment,
    Balance,
    Balanced,
    CarryDone,
    CarryOut,
    Dismissed,
    Go,
    MovedCount,
    Position,
    Ready,
    Release,
    Role,
    Side,
    Sighting,
    Where,
)

__all__ = ["Coordination"]


@dataclass(slots=True)
class _Joint:
    """A joint carry this robot is in."""

    assignment: Assignment
    legs: list[Point] = field(default_factory=list)  # the leader's plan
    ready: set[int] = field(default_factory=set)  # legs this robot is ready for
    partner_ready: set[int] = field(default_factory=set)  # legs the partner is ready for

    @property
    def obj(self) -> int:
        return self.assignment.object.obj

    @property
    def partner(self) -> int:
        return self.assignment.partner


class Coordination(BoxLayer):
    """Agrees on balancing with the partner and paces the joint carry; see the module docs."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.joint: _Joint | None = None
        self.early: Balance | None = None  # a leader's Balance that came before our Assignment

    # -- the rule ---------------------------------------------------------------------------

    def choose_sides(
        self, leader: int, leader_at: Point, helper: int, helper_at: Point, box: Sighting
    ) -> tuple[Side, Side]:
        """The sides the leader and the helper lift ``box`` from (AgreeOnBalancing's rule).

        Args:
            leader: the leader's id.
            leader_at: where the leader stands now.
            helper: the helper's id.
            helper_at: where the helper stands now.
            box: the object.

        Returns:
            ``(leader's side, helper's side)``, opposite sides of the object.
        """
        centre = (box.x, box.y)
        leader_side, _ = nearest_side(leader_at, centre, box.size)
        helper_side, _ = nearest_side(helper_at, centre, box.size)
        if helper_side is leader_side.opposite:
            return leader_side, helper_side

        def walks(sides: tuple[Side, Side]) -> tuple[float, float, int]:
            # The longer walk first, then the shorter; then the lower id's side order.
            there = (
                distance(leader_at, side_point(centre, sides[0], box.size)),
                distance(helper_at, side_point(centre, sides[1], box.size)),
            )
            first = sides[0] if leader < helper else sides[1]
            return max(there), min(there), first

        return min(((side, side.opposite) for side in Side), key=walks)

    def solo_side(self, here: Point, box: Sighting) -> Side:
        """The side a robot alone lifts ``box`` from: the nearest."""
        return nearest_side(here, (box.x, box.y), box.size)[0]

    # -- from the layers of this robot ------------------------------------------------------

    async def store_intra_msg(self, msg: Message) -> None:
        """Assignments and dismissals from Task; readiness and completions from Action."""
        match msg:
            case Assignment(role=Role.SOLO):
                await self._solo(msg)
            case Assignment(role=Role.LEADER):
                await self._lead(msg)
            case Assignment(role=Role.HELPER):
                await self._help(msg)
            case Dismissed(obj=obj):
                if self.joint is not None and self.joint.obj == obj:
                    self.joint = None
            case Ready():
                self._ready(msg)
            case CarryDone(obj=obj):
                if self.joint is not None and self.joint.obj == obj:
                    self.joint = None
                self.send_up(CarryDone(obj))
            case MovedCount(moved=moved):
                if self.learn_moved(moved):
                    self.send_up(MovedCount(moved))
            case _:
                self.unexpected(msg, "not a message Coordination takes from its neighbours")

    async def _where(self) -> Point:
        here = await self.request_down(Where(), reply=Position)
        return (here.x, here.y)

    async def _solo(self, assignment: Assignment) -> None:
        box = assignment.object
        side = self.solo_side(await self._where(), box)
        speed = self.params.carrying_speed(box.weight)
        self.send_down(CarryOut(box, Role.SOLO, side, speed))  # InformAction

    async def _lead(self, assignment: Assignment) -> None:
        """AgreeOnBalancing, as the leader: propose, take the helper's answer, inform Action."""
        box, partner = assignment.object, assignment.partner
        here = await self._where()
        joint = self.joint = _Joint(
            assignment, legs((box.x, box.y), (box.drop_x, box.drop_y), self.params.leg_length)
        )
        speed = self.params.carrying_speed(box.weight, assignment.partner_payload)
        answer = await self.request(
            partner,
            Balance(box.obj, here[0], here[1], speed),
            reply=Balanced,
            timeout=self.params.timeout,
            retries=self.params.retries,
        )
        if answer.msg_type != MsgType.ACCEPT or answer.obj != box.obj:
            # A helper committed to the carry never refuses: the protocol is broken.
            raise RuntimeError(
                f"robot {self.robot_id}: robot {partner} refused to balance object {box.obj}"
            )
        if self.joint is not joint:
            return  # cannot happen: Task hands one carry at a time
        self.send_down(CarryOut(box, Role.LEADER, answer.leader_side, answer.speed, partner))

    async def _help(self, assignment: Assignment) -> None:
        self.joint = _Joint(assignment)
        early, self.early = self.early, None
        if early is not None:
            await self._balance(early)

    # -- from the partner -------------------------------------------------------------------

    async def handle_msg(self, msg: Message) -> None:
        """The leader's Balance, Go and Release; the helper's Ready."""
        match msg:
            case Balance(msg_type=MsgType.NEGOTIATION):
                await self._balance(msg)
            case Ready():
                joint = self._with(msg.robot_id, msg.obj, Role.LEADER)
                if joint is None:
                    self.late(msg, "no joint carry of that object with that robot, as leader")
                    return
                joint.partner_ready.add(msg.leg)
                self._step(joint, msg.leg)
            case Go(obj=obj, leg=leg, x=x, y=y, at=at):
                if self._with(msg.robot_id, obj, Role.HELPER) is None:
                    self.late(msg, "no joint carry of that object with that robot, as helper")
                    return
                self.send_down(Go(obj, leg, x, y, at))
            case Release(obj=obj, at=at):
                if self._with(msg.robot_id, obj, Role.HELPER) is None:
                    self.late(msg, "no joint carry of that object with that robot, as helper")
                    return
                self.send_down(Release(obj, at))
            case _:
                self.unexpected(msg, "not a message Coordination exchanges with other robots")

    async def _balance(self, request: Balance) -> None:
        """AgreeOnBalancing as the helper: sides by the rule, the slower speed; InformAction."""
        joint = self._with(request.robot_id, request.obj, Role.HELPER)
        if joint is None:
            # Our Task's Assignment is still on its way (it left before the leader
            # heard our ACCEPT, but another robot's message can overtake it).
            self.early = request
            return
        box = joint.assignment.object
        here = await self._where()
        leader_side, helper_side = self.choose_sides(
            request.robot_id, (request.x, request.y), self.robot_id, here, box
        )
        own = self.params.carrying_speed(box.weight, joint.assignment.partner_payload)
        speed = min(own, request.speed)
        self.reply(request, Balanced(box.obj, leader_side, helper_side, speed))
        self.send_down(CarryOut(box, Role.HELPER, helper_side, speed, request.robot_id))

    def _with(self, partner: int, obj: int, role: Role) -> _Joint | None:
        """The joint carry of ``obj`` with ``partner`` in which this robot is ``role``."""
        joint = self.joint
        if joint is None or joint.obj != obj or joint.partner != partner:
            return None
        return joint if joint.assignment.role is role else None

    # -- keeping in step --------------------------------------------------------------------

    def _ready(self, ready: Ready) -> None:
        joint = self.joint
        if joint is None or joint.obj != ready.obj:
            self.unexpected(ready, "no joint carry of that object")
            return
        if joint.assignment.role is Role.HELPER:
            self.send(joint.partner, Ready(ready.obj, ready.leg))
            return
        joint.ready.add(ready.leg)
        self._step(joint, ready.leg)

    def _step(self, joint: _Joint, leg: int) -> None:
        """The leader, once both robots are ready for ``leg``: start it, or the put-down."""
        if leg not in joint.ready or leg not in joint.partner_ready:
            return
        at = self.clock.now() + self.params.sync_margin
        if leg < len(joint.legs):
            x, y = joint.legs[leg]
            self.send(joint.partner, Go(joint.obj, leg, x, y, at))
            self.send_down(Go(joint.obj, leg, x, y, at))
        else:
            self.send(joint.partner, Release(joint.obj, at))
            self.send_down(Release(joint.obj, at))
