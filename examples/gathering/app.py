"""The gathering as a scenario app: its settings, its checks, and building the swarm."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

from cas_async import ConstantSpeed, Layer, Message, Pose
from cas_async.scenario import LayerSlot, Mission, ScenarioError, SimulationSetup, setting
from cas_async.sim import SimulatedMiddleware

from .drive import Drive
from .messages import MESSAGES
from .objective import Gathered
from .plan import Plan, Point

__all__ = ["DRIVE", "PLAN", "GatheringApp", "GatheringConfig", "Meeting", "Robots", "app"]

PLAN: Final = LayerSlot("plan", Plan, Plan)
"""Level 0: built as ``Plan(home, team, patience)``."""
DRIVE: Final = LayerSlot("drive", Drive, Drive)
"""Level 1, robotic: built as ``Drive(middleware)``."""


@dataclass(frozen=True)
class Robots:
    """The ``[robots]`` table: how many, how fast, and where they start."""

    count: int = setting(5, ge=1, doc="robots in the swarm")
    speed: float = setting(1.0, gt=0, doc="driving speed, metres per second")
    spawn: tuple[Point, Point] = setting(
        ((0.0, 0.0), (10.0, 10.0)), doc="the area they start in: [[x, y] low, [x, y] high]"
    )


@dataclass(frozen=True)
class Meeting:
    """The ``[gathering]`` table: when a robot counts as gathered, and how long it waits."""

    radius: float = setting(0.5, gt=0, doc="gathered within this distance of the meeting point")
    patience: float = setting(2.0, gt=0, doc="seconds to wait for every robot's position")


@dataclass(frozen=True)
class GatheringConfig:
    """Every table of a gathering scenario besides ``[run]`` and ``[world]``."""

    robots: Robots = setting(default_factory=Robots)
    gathering: Meeting = setting(default_factory=Meeting)


class GatheringApp:
    """Robots scattered in a world agree on a meeting point and drive there."""

    name = "Gathering"
    item_name = "robot"
    config_type = GatheringConfig
    stack: Sequence[LayerSlot[Any]] = (PLAN, DRIVE)
    messages: Sequence[type[Message]] = MESSAGES

    def robots(self, config: GatheringConfig) -> dict[str, int]:
        """How many robots the scenario makes, by the key that sets it."""
        return {"robots.count": config.robots.count}

    def check(self, config: GatheringConfig, world: tuple[float, float]) -> None:
        """The spawn area is a rectangle inside the world.

        Raises:
            ScenarioError: naming the key at fault.
        """
        (x0, y0), (x1, y1) = config.robots.spawn
        width, height = world
        problems: list[tuple[str, str]] = []
        if not (0 <= x0 <= x1 <= width and 0 <= y0 <= y1 <= height):
            problems.append(
                (
                    "robots.spawn",
                    f"expected [[x, y] low, [x, y] high] inside the world (0..{width:g}, "
                    f"0..{height:g}), got [[{x0:g}, {y0:g}], [{x1:g}, {y1:g}]]",
                )
            )
        if problems:
            raise ScenarioError(problems)

    def build(self, setup: SimulationSetup[GatheringConfig]) -> Mission:
        """Robots 1..count, each at a random spot of the spawn area."""
        fleet, meeting = setup.config.robots, setup.config.gathering
        low, high = fleet.spawn
        team = range(1, fleet.count + 1)
        homes: dict[int, Point] = {}
        for robot_id in team:
            x, y = setup.rng.uniform(low, high)
            homes[robot_id] = (float(x), float(y))
        plan, drive = setup.layer(PLAN), setup.layer(DRIVE)  # the scenario's [layers], or ours
        robots = []
        for robot_id, home in homes.items():
            setup.environment.add_robot(robot_id, Pose(*home, 0.0), top_speed=fleet.speed)
            if not setup.holds(robot_id):
                continue  # another process runs it (a run across processes)
            middleware = SimulatedMiddleware(
                setup.environment,
                robot_id,
                setup.clock,
                turn_rate=math.inf,  # it turns on the spot, at once
                speed_profile=ConstantSpeed(fleet.speed),
            )
            layers: list[Layer] = [plan(home, team, meeting.patience), drive(middleware)]
            robots.append(setup.robot(robot_id, layers, messages=MESSAGES))
        return Mission(robots, objective=Gathered(homes, meeting.radius, setup.world))


app = GatheringApp()
"""What a scenario's ``app = "examples.gathering.app"`` names."""
