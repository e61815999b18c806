"""The rendezvous application: two layers, the same classes in simulation and in operation.

Robots that meet: every robot drives to the centroid of the homes (starting points)
of the robots present. Each robot applies that rule to the same facts, so they agree
on the point without a leader; when a robot joins or leaves, the facts change and
every robot re-plans.

* :class:`Gather` (application, level 0) learns the others' homes: it broadcasts
  ``Hello`` when it starts, and asks every robot it hears of (``Hello``, or
  ``on_robot_joined``) to ``Introduce`` itself, one request and its reply. A change
  arms the ``"plan"`` timer; the point is chosen when the facts have been still for
  :data:`SETTLE` seconds (robots that start together do not drive to every partial
  answer). It tells everyone when it has ``Arrived``. A robot given ``company`` ends
  once it has stood at the rendezvous with at least that many others, all arrived,
  for ``stay`` seconds.
* :class:`Drive` (robotic, level 1) is the only layer that touches the robot: it
  answers ``Locate`` from the :class:`~cas_async.Middleware`'s pose and drives the
  legs it is sent with ``move_to``. It does not know whether the middleware is the
  simulator's or a hardware driver's.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable
from typing import Final, TypeAlias

from cas_async import Layer, Message, Middleware, RequestTimeout, RobotId

from .messages import (
    Arrived,
    DriveTo,
    Hello,
    Home,
    Introduce,
    Locate,
    Located,
    Reached,
)

__all__ = [
    "INTRODUCE_TIMEOUT",
    "SETTLE",
    "TOLERANCE",
    "Drive",
    "Gather",
    "Point",
    "rendezvous",
]

Point: TypeAlias = tuple[float, float]

SETTLE: Final = 0.5
"""Simulated seconds the robots present must stay unchanged before a new point is chosen."""

TOLERANCE: Final = 1e-6
"""Metres: two points closer than this are the same point."""

INTRODUCE_TIMEOUT: Final = 2.0
"""Simulated seconds an ``Introduce`` request waits per attempt (it is sent 3 times)."""


def rendezvous(homes: Iterable[Point]) -> Point:
    """The centroid of ``homes``.

    ``math.fsum`` is exactly rounded, so every robot computes the very same float
    whatever order it learned the homes in.
    """
    points = list(homes)
    n = len(points)
    return math.fsum(x for x, _ in points) / n, math.fsum(y for _, y in points) / n


def _same(a: Point | None, b: Point | None) -> bool:
    return a is not None and b is not None and math.dist(a, b) <= TOLERANCE


class Gather(Layer):
    """Agrees on the rendezvous with the robots present and drives there.

    Args:
        company: end (``termination_condition``) once this robot and at least this
            many others stand at the rendezvous; ``None``: stay until stopped.
        stay: simulated seconds to stay at the rendezvous once met, before ending.

    Attributes:
        home: where this robot started (``None`` until the first ``inner_process``).
        homes: the other robots present, by id: where each started.
        target: the rendezvous this robot drives to, ``None`` before the first plan.
        arrived: whether it stands at ``target``.
        plans: every rendezvous it chose, in order.
        joined, left: the robots it heard join and leave, in order.
        met: the robots it met at the rendezvous (empty until it has).
        done: whether it has met them and stayed (``termination_condition``).
    """

    def __init__(self, company: int | None = None, *, stay: float = 0.0) -> None:
        self.company = company
        self.stay = stay
        self.done = False
        self.home: Point | None = None
        self.homes: dict[RobotId, Point] = {}
        self.arrivals: dict[RobotId, Point] = {}  # where each robot last said it arrived
        self.target: Point | None = None
        self.arrived = False
        self.leg = 0
        self.plans: list[Point] = []
        self.joined: list[RobotId] = []
        self.left: list[RobotId] = []
        self.met: tuple[RobotId, ...] = ()

    # -- the facts: who is here, and where each started ---------------------------------

    async def inner_process(self) -> None:
        if self.home is None:  # at start: where am I? then, whoever is here, introduce yourselves
            here = await self.request_down(Locate(), reply=Located)
            self.home = (here.x, here.y)
            self.broadcast(Hello())
            self.wake_after(SETTLE, "plan")

    def get_msg_reply(self, msg: Message) -> Message | None:
        # Answered on arrival, even while this layer awaits its own Introduce: two
        # robots that ask each other at once are both answered.
        match msg:
            case Introduce(x=x, y=y) if self.home is not None:
                self._learn(msg.robot_id, (x, y))
                return Home(*self.home)
        return None  # before this robot knows its home: handle_msg answers

    async def handle_msg(self, msg: Message) -> None:
        match msg:
            case Hello():
                await self._introduce(msg.robot_id)
            case Introduce(x=x, y=y) if self.home is not None:
                self._learn(msg.robot_id, (x, y))
                self.reply(msg, Home(*self.home))
            case Arrived(x=x, y=y):
                self.log.debug("robot %s is at (%.3f, %.3f)", msg.robot_id, x, y)
                self.arrivals[msg.robot_id] = (x, y)
                self._check_met()

    async def on_robot_joined(self, robot_id: RobotId) -> None:
        self.joined.append(robot_id)
        self.log.info("robot %s joined", robot_id)
        await self._introduce(robot_id)

    async def on_robot_left(self, robot_id: RobotId) -> None:
        self.left.append(robot_id)
        self.log.info("robot %s left", robot_id)
        self.arrivals.pop(robot_id, None)
        if self.homes.pop(robot_id, None) is not None:
            self.wake_after(SETTLE, "plan")

    async def _introduce(self, robot_id: RobotId) -> None:
        """Asks ``robot_id`` where it started (and tells it where this robot did)."""
        if self.home is None or robot_id in self.homes:
            return  # no home yet: this robot's Hello, still to come, will reach it
        try:
            home = await self.request(
                robot_id, Introduce(*self.home), reply=Home, timeout=INTRODUCE_TIMEOUT, retries=2
            )
        except RequestTimeout as exc:  # RobotGone too: it left meanwhile
            self.log.info("robot %s did not introduce itself: %s", robot_id, exc)
            return
        self._learn(robot_id, (home.x, home.y))

    def _learn(self, robot_id: RobotId, home: Point) -> None:
        if self.homes.get(robot_id) != home:
            self.homes[robot_id] = home
            self.wake_after(SETTLE, "plan")  # arming it again moves it: one plan per settling

    # -- the plan: choose the point, drive there, say so -------------------------------

    async def on_timer(self, key: Hashable) -> None:
        if key == "leave":
            self.done = True
            return
        if key != "plan" or self.home is None:
            return
        target = rendezvous([self.home, *self.homes.values()])
        if not _same(target, self.target):
            self.target, self.arrived = target, False
            self.plans.append(target)
            self.leg += 1
            if self.homes:
                self.log.info(
                    "rendezvous with robots %s at (%.3f, %.3f)", sorted(self.homes), *target
                )
            else:
                self.log.info("alone: going home to (%.3f, %.3f)", *target)
            self.send_down(DriveTo(*target, leg=self.leg))
        elif self.arrived:
            self.broadcast(Arrived(*target))  # newcomers learn that this robot is there

    async def store_intra_msg(self, msg: Message) -> None:
        match msg:
            case Reached(leg=leg) if leg == self.leg and self.target is not None:
                self.arrived = True
                self.log.info("arrived at (%.3f, %.3f)", *self.target)
                self.broadcast(Arrived(*self.target))
                self._check_met()

    def _check_met(self) -> None:
        target = self.target
        if self.company is None or self.met or not self.arrived or target is None:
            return
        others = sorted(self.homes)
        if len(others) >= self.company and all(
            _same(self.arrivals.get(robot_id), target) for robot_id in others
        ):
            self.met = tuple(others)
            self.log.info("met robots %s at (%.3f, %.3f)", others, *target)
            self.wake_after(self.stay, "leave")

    def termination_condition(self) -> bool:
        return self.done


class Drive(Layer):
    """The robotic layer: answers ``Locate`` and drives each ``DriveTo`` leg in turn.

    Args:
        middleware: the robot's motion and perception, simulated or real.
    """

    def __init__(self, middleware: Middleware) -> None:
        self.middleware = middleware

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        match msg:
            case Locate():
                pose = self.middleware.pose()
                return Located(pose.x, pose.y, pose.heading)
        return None

    async def store_intra_msg(self, msg: Message) -> None:
        match msg:
            case DriveTo(x=x, y=y, leg=leg):
                # This layer's messages wait while the robot drives: the next leg
                # starts where this one ends.
                pose = await self.middleware.move_to(x, y)
                self.send_up(Reached(pose.x, pose.y, leg))
