"""Factories for the box-moving tests: parameters, objects, a floor with robots placed by hand."""

from __future__ import annotations

import math
from pathlib import Path

from apps.box_moving.base import Params
from apps.box_moving.floor import Floor
from apps.box_moving.messages import Sighting
from apps.box_moving.records import Box
from cas_async import ConstantSpeed, Message, Pose
from cas_async._wire._message import message_fields
from cas_async.sim import Environment, Motion

SCENARIOS = Path(__file__).resolve().parents[2] / "apps" / "box_moving" / "scenarios"
VIRTUAL = ("run.virtual=true", 'run.transport="memory"')


def params(**changes: object) -> Params:
    """A robot's parameters: payload 10, speed 1, two peers (2 and 3), target 5."""
    values: dict[str, object] = {
        "target": 5,
        "peers": (2, 3),
        "speed": 1.0,
        "payload": 10.0,
        "slowdown": 0.5,
        "lift_time": 1.0,
        "put_down_time": 1.0,
        "leg_length": 2.0,
        "sync_margin": 0.2,
        "retry_interval": 2.0,
        "timeout": 0.5,
        "retries": 2,
    }
    values.update(changes)
    return Params(**values)  # type: ignore[arg-type]


def sighting(obj: int = 1, x: float = 5.0, y: float = 5.0, weight: float = 4.0) -> Sighting:
    """An object of size 1 at ``x, y`` whose drop spot is (9, 5)."""
    return Sighting(obj, x, y, weight, 1.0, 9.0, 5.0)


def floor_with(
    robots: dict[int, tuple[float, float]],
    boxes: list[Box] | None = None,
    payloads: dict[int, float] | None = None,
) -> tuple[Environment, Floor]:
    """An Environment with ``robots`` standing where given, and a Floor over it.

    By default: object 1 (weight 14, size 1) at (5, 5), object 2 (weight 4,
    size 0.5) at (2, 2); the zone is centred on (9, 5), radius 1.5; payloads are
    10 for robot 1 and 6 for the others.
    """
    environment = Environment()
    for robot, (x, y) in robots.items():
        environment.add_robot(robot, Pose(x, y, 0.0))
    if boxes is None:
        boxes = [Box(1, 5.0, 5.0, 14.0, 1.0, 9.0, 5.0), Box(2, 2.0, 2.0, 4.0, 0.5, 9.0, 6.0)]
    if payloads is None:
        payloads = {robot: 10.0 if robot == 1 else 6.0 for robot in robots}
    floor = Floor(environment, boxes, ((9.0, 5.0), 1.5), payloads, slack=0.05)
    return environment, floor


def drive(
    environment: Environment, robot: int, x: float, y: float, t: float, speed: float = 1.0
) -> float:
    """Starts ``robot`` driving straight to ``(x, y)`` at ``speed`` from ``t``; returns its end."""
    here = environment.pose_at(robot, t)
    motion = Motion.straight_to(here, x, y, turn_rate=math.inf, profile=ConstantSpeed(speed))
    environment.start_motion(robot, motion, t)
    return t + motion.duration


def body(msg: Message) -> tuple[object, ...]:
    """A message's class and fields, without the header: what two copies have in common."""
    return (type(msg).__name__, *(getattr(msg, name) for name in message_fields(type(msg))))


def bodies(messages: list[Message]) -> list[tuple[object, ...]]:
    """:func:`body` of each message."""
    return [body(msg) for msg in messages]
