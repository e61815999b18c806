"""The box-moving application as a cas_async simulation app: scenario checks, building the swarm."""

from __future__ import annotations

import math
from typing import Any, Final

from cas_async import ConstantSpeed, Layer, Pose
from cas_async.scenario import LayerSlot, Mission, ScenarioError, SimulationSetup
from cas_async.sim import SimulatedMiddleware

from .action import Action
from .base import BoxLayer, Params
from .config import BoxMovingConfig
from .coordination import Coordination
from .decision_making import DecisionMaking
from .floor import Floor
from .gripper import FloorGripper
from .layout import lift_problems, place_objects, spot_count
from .messages import MESSAGES
from .objective import MoveObjects
from .scene import floor_scene
from .task import Task

__all__ = [
    "ACTION_SLOT",
    "COORDINATION_SLOT",
    "DECISION_SLOT",
    "MESSAGES",
    "TASK_SLOT",
    "BoxMoving",
]

DECISION_SLOT: Final = LayerSlot("decision_making", BoxLayer, DecisionMaking)
TASK_SLOT: Final = LayerSlot("task", BoxLayer, Task)
COORDINATION_SLOT: Final = LayerSlot("coordination", BoxLayer, Coordination)
ACTION_SLOT: Final = LayerSlot("action", Action, Action)
"""The four levels, top first; a scenario's ``[layers]`` may replace any of them.

The upper three are built as ``cls(params)`` (a replacement subclasses
:class:`~apps.box_moving.base.BoxLayer`), the Action layer as
``cls(params, middleware, gripper)`` (a replacement subclasses :class:`Action`).
"""


def _inside(x: float, y: float, margin: float, world: tuple[float, float]) -> bool:
    return margin <= x <= world[0] - margin and margin <= y <= world[1] - margin


class BoxMoving:
    """Robots moving objects to a destination, alone or in pairs (thesis §3.2.1, §4.4)."""

    name = "Box Moving"
    item_name = "object"
    config_type = BoxMovingConfig
    stack: tuple[LayerSlot[Any], ...] = (DECISION_SLOT, TASK_SLOT, COORDINATION_SLOT, ACTION_SLOT)
    messages = MESSAGES

    def robots(self, config: BoxMovingConfig) -> dict[str, int]:
        """One robot per ``[[robots]]`` table."""
        return {"robots": len(config.robots)}

    def check(self, config: BoxMovingConfig, world: tuple[float, float]) -> None:
        """Everything inside the world, enough drop spots, every object liftable.

        Raises:
            ScenarioError: naming each key at fault.
        """
        problems: list[tuple[str, str]] = []
        where = f"inside the world (0..{world[0]:g}, 0..{world[1]:g})"
        if not config.robots:
            problems.append(("robots", "expected at least one robot"))
        for index, robot in enumerate(config.robots):
            if not _inside(robot.x, robot.y, 0.0, world):
                problems.append((f"robots[{index}]", f"expected a position {where}"))
        zone = config.destination
        for index, spec in enumerate(config.objects):
            if not _inside(spec.x, spec.y, spec.size / 2, world):
                problems.append((f"objects[{index}]", f"expected an object wholly {where}"))
            elif ((spec.x - zone.at[0]) ** 2 + (spec.y - zone.at[1]) ** 2) ** 0.5 <= zone.radius:
                problems.append((f"objects[{index}]", "lies in the destination zone already"))
        scatter = config.scatter
        if scatter.count:
            for key, (low, high) in (
                ("scatter.weight", scatter.weight),
                ("scatter.size", scatter.size),
            ):
                if low > high:
                    problems.append(
                        (key, f"expected [min, max] with min <= max, got [{low:g}, {high:g}]")
                    )
            corners = (scatter.area_min, scatter.area_max)
            if any(not _inside(x, y, scatter.size[1] / 2, world) for x, y in corners):
                problems.append(("scatter", f"expected an area whose objects lie wholly {where}"))
            if any(low > high for low, high in zip(*corners, strict=True)):
                problems.append(
                    ("scatter.area_max", "expected a corner above and right of area_min")
                )
        if not _inside(zone.at[0], zone.at[1], 0.0, world):
            problems.append(("destination.at", f"expected a point {where}"))
        spots = spot_count(config)
        if spots < config.object_count:
            problems.append(
                (
                    "destination.radius",
                    f"too small: it holds {spots} drop spots, for {config.object_count} objects "
                    f"of size up to {config.largest_size:g}",
                )
            )
        if config.mission.target > config.object_count:
            problems.append(
                (
                    "mission.target",
                    f"expected at most {config.object_count} (the objects), "
                    f"got {config.mission.target}",
                )
            )
        problems += lift_problems(config)
        if problems:
            raise ScenarioError(problems)

    def build(self, setup: SimulationSetup[BoxMovingConfig]) -> Mission:
        """The robots (ids from 1, as listed), the Floor with its objects, and the objective."""
        config = setup.config
        roster = tuple(range(1, len(config.robots) + 1))
        boxes = place_objects(config, setup.rng)
        floor = Floor(
            setup.environment,
            boxes,
            (config.destination.at, config.destination.radius),
            {robot_id: spec.payload for robot_id, spec in zip(roster, config.robots, strict=True)},
            slack=config.floor.slack,
        )
        decision, task = setup.layer(DECISION_SLOT), setup.layer(TASK_SLOT)
        coordination, action = setup.layer(COORDINATION_SLOT), setup.layer(ACTION_SLOT)
        robots = []
        for robot_id, spec in zip(roster, config.robots, strict=True):
            params = Params(
                target=config.mission.target,
                peers=tuple(peer for peer in roster if peer != robot_id),
                speed=spec.speed,
                payload=spec.payload,
                slowdown=config.carrying.slowdown,
                lift_time=config.carrying.lift_time,
                put_down_time=config.carrying.put_down_time,
                leg_length=config.coordination.leg_length,
                sync_margin=config.coordination.sync_margin,
                retry_interval=config.partners.retry_interval,
                timeout=config.messaging.timeout,
                retries=config.messaging.retries,
            )
            heading = spec.heading
            if heading is None:
                heading = float(setup.rng.uniform(-math.pi, math.pi))
            setup.environment.add_robot(robot_id, Pose(spec.x, spec.y, heading))
            middleware = SimulatedMiddleware(
                setup.environment,
                robot_id,
                setup.clock,
                turn_rate=config.carrying.turn_rate,
                speed_profile=ConstantSpeed(spec.speed),
            )
            layers: list[Layer] = [
                decision(params),
                task(params),
                coordination(params),
                action(params, middleware, FloorGripper(floor, robot_id, setup.clock)),
            ]
            robots.append(setup.robot(robot_id, layers, messages=MESSAGES))
        coordination_rule = f"{coordination.__module__}.{coordination.__qualname__}"
        return Mission(
            robots,
            groups={"Robot": list(roster)},
            extra=lambda: {"coordination": coordination_rule},
            objective=MoveObjects(floor, config.mission.target, setup.world),
            scene=floor_scene(boxes, (config.destination.at, config.destination.radius)),
        )
