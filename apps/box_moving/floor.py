"""The Floor: the box-moving app's simulated world of objects, and the authority over them.

It knows every object (where it lies, its weight, size and drop spot), who lifts
each, and which are moved; the robots' poses come from the
:class:`~cas_async.sim.Environment`. A carried object moves with its lifters:
its centre keeps the offset it had from each lifter when the carry began (the
mean of the two for a joint carry: the midpoint of the pair, which stands on
opposite sides). Only the Action layer reaches it, through a
:class:`~apps.box_moving.gripper.Gripper`.

The invariant, checked on every operation (lift, put-down), at every motion a
lifter starts or ends (through ``Environment.watch_motions``), and in full by
:meth:`Floor.audit` at every sample of a run:

* an object is lifted by one robot that can lift it alone and named no partner,
  or by two robots whose payloads together lift it and who each named the other;
  anything else is an *incomplete* pair, which may not move: a lifter of an
  incomplete pair that sets off is a violation (a joint carry never starts
  without both agreeing);
* a robot lifts one object at a time, from one of its sides, standing there;
* the lifters of a joint carry stay within the object's size (plus ``slack``)
  of each other: the object is never in two places;
* a robot that put an object down no longer moves it, and a moved object (put
  down inside the destination zone) is never lifted again.

A violation raises :class:`FloorViolation`, naming the robot, the object and
the instant. The Floor records every event and each object's path (the
positions it passed through, with their instants) for the objective's
measures and figure.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

from cas_async.sim import Environment, Motion

from .geometry import Point, distance, side_point
from .messages import Side
from .records import Box, Delivery, FloorEvent, FloorEventKind, FloorViolation

__all__ = ["Floor"]


@dataclass(slots=True)
class _Grip:
    """One lifter's hold: from where, naming whom, with what offset to the centre."""

    robot: int
    side: Side
    partner: int | None
    at: Point  # where the robot stood at the lift (or when its pair last broke up)
    offset: Point  # centre minus the robot's position, kept while the carry is complete


@dataclass(slots=True)
class _Object:
    box: Box
    x: float  # where it lies, while no complete carry moves it
    y: float
    grips: dict[int, _Grip] = field(default_factory=dict)
    moved_at: float | None = None
    claimed_by: int | None = None
    claimed_at: float | None = None
    lifted_at: float | None = None
    carriers: tuple[int, ...] = ()
    path: list[tuple[float, float, float]] = field(default_factory=list)


class Floor:
    """The objects of a box-moving run, and who lifts them; see the module docs.

    Args:
        environment: the robots' world (their poses); the Floor watches their motions.
        boxes: the objects, each with a unique id.
        zone: the destination zone's centre and radius.
        payloads: each robot's payload, by id.
        slack: how far a robot may be from where the invariant puts it (its side
            point, the pair's distance, the place it must not leave), in distance units.

    Raises:
        ValueError: two objects share an id, or ``slack`` is not a number >= 0.
    """

    def __init__(
        self,
        environment: Environment,
        boxes: Sequence[Box],
        zone: tuple[Point, float],
        payloads: Mapping[int, float],
        *,
        slack: float = 0.1,
    ) -> None:
        if len({box.obj for box in boxes}) < len(boxes):
            raise ValueError("Floor: two objects share an id")
        if not (math.isfinite(slack) and slack >= 0):
            raise ValueError(f"Floor: slack must be a number >= 0, got {slack!r}")
        self._environment = environment
        self._objects = {box.obj: _Object(box, box.x, box.y) for box in boxes}
        for state in self._objects.values():
            state.path.append((0.0, state.box.x, state.box.y))  # where it lies at the start
        self._zone = zone
        self._payloads = dict(payloads)
        self._slack = slack
        self._gripping: dict[int, int] = {}  # robot -> the object it lifts
        self._events: list[FloorEvent] = []
        self._subscribers: list[Callable[[FloorEvent], None]] = []
        self._moved = 0
        environment.watch_motions(self._on_motion)

    # -- reading ---------------------------------------------------------------------------

    @property
    def boxes(self) -> tuple[Box, ...]:
        """Every object as it was placed, by id."""
        return tuple(state.box for state in self._objects.values())

    @property
    def zone(self) -> tuple[Point, float]:
        """The destination zone's centre and radius."""
        return self._zone

    @property
    def moved(self) -> int:
        """How many objects are moved."""
        return self._moved

    @property
    def events(self) -> tuple[FloorEvent, ...]:
        """Every event so far, in order."""
        return tuple(self._events)

    def subscribe(self, callback: Callable[[FloorEvent], None]) -> None:
        """Calls ``callback(event)`` after every event."""
        self._subscribers.append(callback)

    def lifters(self) -> set[int]:
        """The robots lifting an object now."""
        return set(self._gripping)

    def is_moved(self, obj: int) -> bool:
        """Whether ``obj`` is moved."""
        return self._objects[obj].moved_at is not None

    def position(self, obj: int, t: float) -> Point:
        """Where ``obj``'s centre is at instant ``t`` (``t`` not before the last event)."""
        state = self._objects[obj]
        if self._complete(state):
            return self._carried(state, t)
        return (state.x, state.y)

    def path(self, obj: int) -> list[tuple[float, float, float]]:
        """The instants and positions ``obj`` passed through: ``(t, x, y)``, from where it lay."""
        return list(self._objects[obj].path)

    def carriers(self, obj: int) -> tuple[int, ...]:
        """The robots of ``obj``'s current or last complete carry (empty: never carried)."""
        return self._objects[obj].carriers

    def deliveries(self) -> list[Delivery]:
        """The moved objects, in the order they were moved."""
        done = [state for state in self._objects.values() if state.moved_at is not None]
        done.sort(key=lambda state: (state.moved_at, state.box.obj))
        return [
            Delivery(
                state.box.obj,
                state.moved_at if state.moved_at is not None else math.nan,
                _first(state.claimed_at, state.lifted_at, 0.0),
                state.carriers,
                _length(state.path),
            )
            for state in done
        ]

    def free(self, robot: int) -> list[Box]:
        """What ``robot``'s sensors see: objects not moved, lifted nor claimed by another robot.

        Each as it lies now (its centre where it is), by id.
        """
        seen = []
        for state in self._objects.values():
            if state.moved_at is not None or state.grips:
                continue
            if state.claimed_by not in (None, robot):
                continue
            seen.append(replace(state.box, x=state.x, y=state.y))
        return seen

    # -- operations ------------------------------------------------------------------------

    def claim(self, robot: int, obj: int, t: float) -> None:
        """``robot`` marks ``obj`` as its selection (the last mark wins: it is a label).

        Raises:
            FloorViolation: no such object, or it is moved already.
        """
        state = self._object(robot, obj, t)
        if state.moved_at is not None:
            raise FloorViolation(
                f"claimed an object moved at t={state.moved_at:.6g}", robot=robot, obj=obj, t=t
            )
        state.claimed_by, state.claimed_at = robot, t
        self._record(t, FloorEventKind.CLAIMED, state, (robot,))

    def unclaim(self, robot: int, obj: int, t: float) -> None:
        """``robot`` takes its mark off ``obj`` (unless another robot marked it since)."""
        state = self._object(robot, obj, t)
        if state.claimed_by == robot:
            state.claimed_by = None
            self._record(t, FloorEventKind.UNCLAIMED, state, (robot,))

    def lift(self, robot: int, obj: int, side: Side, partner: int | None, t: float) -> None:
        """``robot`` lifts ``obj`` from ``side`` at ``t``, naming its ``partner`` (``None``: alone).

        Raises:
            FloorViolation: the lift breaks the invariant (see the module docs);
                nothing changes then.
        """
        state = self._object(robot, obj, t)
        box = state.box

        def refuse(problem: str) -> FloorViolation:
            return FloorViolation(problem, robot=robot, obj=obj, t=t)

        if state.moved_at is not None:
            raise refuse(f"lifted an object moved at t={state.moved_at:.6g}: it stays put")
        self._check(state, t)  # what the lifters already there did
        holding = self._gripping.get(robot)
        if holding is not None:
            raise refuse(f"lifted a second object: it holds object {holding}")
        if len(state.grips) >= 2:
            raise refuse(f"lifted an object two robots ({_names(state.grips)}) lift")
        payload = self._payload(robot, obj, t)
        if partner is None:
            if box.weight > payload:
                raise refuse(
                    f"lifted alone an object of weight {box.weight:g}, beyond its payload "
                    f"{payload:g}: it takes a partner"
                )
            if state.grips:
                raise refuse(f"lifted alone an object robot {_names(state.grips)} lifts")
        else:
            if partner == robot:
                raise refuse("named itself as its partner")
            together = payload + self._payload(partner, obj, t)
            if box.weight > together:
                raise refuse(
                    f"and robot {partner} cannot lift weight {box.weight:g} together "
                    f"(payloads {together:g})"
                )
            for other in state.grips.values():
                if other.robot != partner or other.partner != robot:
                    named = "nobody" if other.partner is None else f"robot {other.partner}"
                    raise refuse(
                        f"named robot {partner} as partner, but robot {other.robot}, which "
                        f"lifts it, named {named}: the pair does not agree"
                    )
        if any(grip.side == side for grip in state.grips.values()):
            raise refuse(f"lifted from the {side.name.lower()} side, where another robot is")
        here = self._where(robot, t)
        spot = side_point((state.x, state.y), side, box.size)
        if distance(here, spot) > self._slack:
            raise refuse(
                f"lifted from ({here[0]:.6g}, {here[1]:.6g}), {distance(here, spot):.3g} from "
                f"its {side.name.lower()} side point ({spot[0]:.6g}, {spot[1]:.6g})"
            )
        offset = (state.x - here[0], state.y - here[1])
        state.grips[robot] = _Grip(robot, side, partner, here, offset)
        self._gripping[robot] = obj
        if state.lifted_at is None:
            state.lifted_at = t
        self._record(t, FloorEventKind.LIFTED, state, (robot,))
        if self._complete(state):
            state.carriers = tuple(sorted(state.grips))
            self._record(t, FloorEventKind.CARRIED, state, state.carriers)
            state.path.append((t, state.x, state.y))

    def put_down(self, robot: int, obj: int, t: float) -> None:
        """``robot`` puts ``obj`` down at ``t``; the last lifter's put-down in the zone moves it.

        Raises:
            FloorViolation: ``robot`` does not lift ``obj``, or the carry broke the
                invariant before the put-down.
        """
        state = self._object(robot, obj, t)
        if robot not in state.grips:
            raise FloorViolation("put down an object it does not lift", robot=robot, obj=obj, t=t)
        self._check(state, t)
        if self._complete(state):
            state.x, state.y = self._carried(state, t)
            state.path.append((t, state.x, state.y))
        del state.grips[robot]
        del self._gripping[robot]
        for grip in state.grips.values():
            # The other lifter is alone now: from here it may not move.
            grip.at = self._where(grip.robot, t)
        self._record(t, FloorEventKind.PUT_DOWN, state, (robot,))
        if not state.grips:
            centre, radius = self._zone
            if distance((state.x, state.y), centre) <= radius:
                state.moved_at = t
                state.claimed_by = None
                self._moved += 1
                self._record(t, FloorEventKind.MOVED, state, state.carriers)

    # -- the invariant ---------------------------------------------------------------------

    def audit(self, t: float) -> None:
        """Checks the whole invariant at instant ``t`` (see the module docs).

        Raises:
            FloorViolation: the first violation found.
        """
        for robot, obj in self._gripping.items():
            if robot not in self._objects[obj].grips:
                raise FloorViolation(
                    "is filed as lifting an object it does not", robot=robot, obj=obj, t=t
                )
        for state in self._objects.values():
            if state.moved_at is not None:
                centre, radius = self._zone
                if state.grips or distance((state.x, state.y), centre) > radius:
                    robot = next(iter(state.grips), 0)
                    raise FloorViolation(
                        "a moved object is lifted or outside the zone",
                        robot=robot,
                        obj=state.box.obj,
                        t=t,
                    )
            self._check(state, t)

    def _check(self, state: _Object, t: float) -> None:
        """The invariant for one object at ``t``: a pair together, an incomplete pair still."""
        obj, slack = state.box.obj, self._slack
        if self._complete(state):
            if len(state.grips) == 2:
                a, b = sorted(state.grips)
                apart = distance(self._where(a, t), self._where(b, t))
                if apart > state.box.size + slack:
                    raise FloorViolation(
                        f"and robot {b} carry it {apart:.6g} apart, beyond its size "
                        f"{state.box.size:g}: it would be in two places",
                        robot=a,
                        obj=obj,
                        t=t,
                    )
            return
        for grip in state.grips.values():
            here = self._where(grip.robot, t)
            if distance(here, grip.at) > slack:
                raise FloorViolation(self._alone(state, grip), robot=grip.robot, obj=obj, t=t)

    def _on_motion(self, robot: int, motion: Motion, start: float) -> None:
        """A lifter starts or ends a motion: check its object; note the object's path."""
        obj = self._gripping.get(robot)
        if obj is None:
            return
        state = self._objects[obj]
        if not self._complete(state):
            if motion.length > 0:
                grip = state.grips[robot]
                raise FloorViolation(self._alone(state, grip), robot=robot, obj=obj, t=start)
            return
        self._check(state, start)
        x, y = self._carried(state, start)
        state.path.append((start, x, y))

    def _alone(self, state: _Object, grip: _Grip) -> str:
        if grip.partner is None:
            return "moved an object it lifts alone while another robot lifts it too"
        partner = state.grips.get(grip.partner)
        if partner is None:
            why = f"robot {grip.partner} does not lift it"
        else:
            why = f"robot {grip.partner} named {partner.partner}"
        return (
            f"moved an object it lifts with robot {grip.partner}, but {why}: the pair is incomplete"
        )

    # -- helpers ---------------------------------------------------------------------------

    @staticmethod
    def _complete(state: _Object) -> bool:
        """Whether the lifters make a carry: one robot alone, or two naming each other."""
        grips = list(state.grips.values())
        if len(grips) == 1:
            return grips[0].partner is None
        if len(grips) == 2:
            a, b = grips
            return a.partner == b.robot and b.partner == a.robot
        return False

    def _carried(self, state: _Object, t: float) -> Point:
        """A complete carry's centre at ``t``: each lifter's position plus its offset, averaged."""
        xs, ys = [], []
        for grip in state.grips.values():
            x, y = self._where(grip.robot, t)
            xs.append(x + grip.offset[0])
            ys.append(y + grip.offset[1])
        return (math.fsum(xs) / len(xs), math.fsum(ys) / len(ys))

    def _where(self, robot: int, t: float) -> Point:
        pose = self._environment.pose_at(robot, t)
        return (pose.x, pose.y)

    def _object(self, robot: int, obj: int, t: float) -> _Object:
        state = self._objects.get(obj)
        if state is None:
            raise FloorViolation("no such object on the floor", robot=robot, obj=obj, t=t)
        return state

    def _payload(self, robot: int, obj: int, t: float) -> float:
        payload = self._payloads.get(robot)
        if payload is None:
            raise FloorViolation("is not a robot of this floor", robot=robot, obj=obj, t=t)
        return payload

    def _record(
        self, t: float, kind: FloorEventKind, state: _Object, robots: tuple[int, ...]
    ) -> None:
        event = FloorEvent(t, kind, state.box.obj, robots, state.x, state.y)
        self._events.append(event)
        for subscriber in self._subscribers:
            subscriber(event)


def _names(grips: Mapping[int, _Grip]) -> str:
    return " and ".join(str(robot) for robot in sorted(grips))


def _first(*values: float | None) -> float:
    return next(value for value in values if value is not None)


def _length(path: Sequence[tuple[float, float, float]]) -> float:
    return math.fsum(
        math.hypot(x1 - x0, y1 - y0) for (_, x0, y0), (_, x1, y1) in itertools.pairwise(path)
    )
