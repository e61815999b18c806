"""The Fire Brigade as a cas_async simulation app: scenario checks and building the swarm.

Its five levels are named (``stack``), so a scenario's ``[layers]`` may replace any
of them (``task = "my_package.PatientTask"``); the partner strategy may also be named
by ``strategy.name``, and ``[layers] strategy`` wins over it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Final

from cas_async import Layer, Message, Pose
from cas_async.scenario import LayerSlot, Mission, ScenarioError, SimulationSetup
from cas_async.sim import SimulatedHands, SimulatedMiddleware

from .action import Action
from .base import BrigadeLayer, Params, Peers, Point
from .config import FireBrigadeConfig
from .goal import Goal
from .group_activity import GroupActivity
from .lines import LineShare, segments
from .messages import MESSAGES, Kind
from .scene import brigade_scene
from .strategies import TimeStrategy, strategy_class
from .strategy import Strategy
from .task import Task

__all__ = ["ACTION", "GOAL", "GROUP_ACTIVITY", "MESSAGES", "STRATEGY", "TASK", "FireBrigade"]

GOAL: Final = LayerSlot("goal", BrigadeLayer, Goal)
"""Level 0: decides to move a bucket, and to which Sink; built as ``Goal(params)``."""
STRATEGY: Final = LayerSlot("strategy", Strategy, TimeStrategy)
"""Level 1: finds a partner; a :class:`Strategy` (default: ``strategy.name``'s)."""
GROUP_ACTIVITY: Final = LayerSlot("group_activity", BrigadeLayer, GroupActivity)
"""Level 2: agrees on the meeting point; built as ``GroupActivity(params)``."""
TASK: Final = LayerSlot("task", BrigadeLayer, Task)
"""Level 3: rotates, moves, waits and swaps; built as ``Task(params)``."""
ACTION: Final = LayerSlot("action", Action, Action)
"""Level 4: the robotic layer; built as ``Action(params, middleware, hands)``."""


THESIS_SNAPSHOTS: Final = (35, 95, 125, 200)
"""The exchange counts of the thesis's Fig. 34: the figures show the robots there."""

_REACH: Final = 1e-6
"""How close two robots must be for a hand-over (they meet at the same point)."""


def _inside(point: Point, world: Point) -> bool:
    return 0 <= point[0] <= world[0] and 0 <= point[1] <= world[1]


class FireBrigade:
    """Generators, Sinks and Transporters moving buckets (thesis chapter 5)."""

    name = "Fire Brigade"
    item_name = "bucket"
    config_type = FireBrigadeConfig
    stack: Sequence[LayerSlot[Any]] = (GOAL, STRATEGY, GROUP_ACTIVITY, TASK, ACTION)
    messages: Sequence[type[Message]] = MESSAGES

    def robots(self, config: FireBrigadeConfig) -> dict[str, int]:
        """Stations (every copy of the layout) and Transporters, counted without placing any."""
        stations = config.stations
        per_copy = len(stations.generators) + len(stations.sinks)
        return {
            "stations.repeat" if stations.repeat > 1 else "stations": per_copy * stations.repeat,
            "transporters.count": config.transporters.count,
        }

    def check(self, config: FireBrigadeConfig, world: tuple[float, float]) -> None:
        """Robots inside the world, a sensible spawn area and speeds, a known strategy.

        Raises:
            ScenarioError: naming each key at fault.
        """
        problems: list[tuple[str, str]] = []
        where = f"inside the world (0..{world[0]:g}, 0..{world[1]:g})"
        stations = config.stations
        for key, points in (
            ("stations.generators", stations.generators),
            ("stations.sinks", stations.sinks),
        ):
            if not points:
                problems.append((key, "expected at least one position, got none"))
            for index, point in enumerate(points):
                # Each listed position once: the first of its copies that is outside.
                copies = stations.placed((point,))
                outside = next((k for k, at in enumerate(copies) if not _inside(at, world)), None)
                if outside is not None:
                    at = copies[outside]
                    which = f" (copy {outside + 1} of {len(copies)})" if len(copies) > 1 else ""
                    problems.append(
                        (
                            f"{key}[{index}]",
                            f"expected a position {where}, got [{at[0]:g}, {at[1]:g}]{which}",
                        )
                    )
        everyone = [*stations.placed(stations.generators), *stations.placed(stations.sinks)]
        if len(set(everyone)) < len(everyone):
            problems.append(("stations", "two stations stand at the same position"))
        fleet = config.transporters
        for key, point in (
            ("transporters.spawn_min", fleet.spawn_min),
            ("transporters.spawn_max", fleet.spawn_max),
        ):
            if not _inside(point, world):
                problems.append(
                    (key, f"expected a corner {where}, got [{point[0]:g}, {point[1]:g}]")
                )
        if fleet.spawn_min[0] > fleet.spawn_max[0] or fleet.spawn_min[1] > fleet.spawn_max[1]:
            problems.append(
                (
                    "transporters.spawn_max",
                    "expected a corner above and to the right "
                    f"of spawn_min {list(fleet.spawn_min)}, got {list(fleet.spawn_max)}",
                )
            )
        if fleet.min_speed > fleet.speed:
            problems.append(
                (
                    "transporters.min_speed",
                    f"expected at most speed ({fleet.speed:g}), got {fleet.min_speed:g}",
                )
            )
        messaging = config.messaging
        if messaging.patience <= fleet.handover_time + messaging.timeout:
            # A giver says nothing while it hands over, and a receiver calls every
            # timeout: with less patience every receiver gives up mid-hand-over.
            problems.append(
                (
                    "messaging.patience",
                    "expected more than transporters.handover_time + messaging.timeout "
                    f"({fleet.handover_time:g} + {messaging.timeout:g}), got {messaging.patience:g}"
                    ": a receiver would give up during every hand-over",
                )
            )
        try:
            strategy_class(config.strategy.name)
        except ValueError as exc:
            problems.append(("strategy.name", str(exc)))
        if problems:
            raise ScenarioError(problems)

    def build(self, setup: SimulationSetup[FireBrigadeConfig]) -> Mission:
        """Generators, then Sinks, then Transporters (spawned at random), ids from 1."""
        config = setup.config
        fleet, rng = config.transporters, setup.rng
        reach = setup.environment.interaction_range
        if reach is not None and config.strategy.range > reach:
            raise ScenarioError(
                [
                    (
                        "strategy.range",
                        f"expected at most network.range ({reach:g}): no robot senses "
                        f"farther, got {config.strategy.range:g}",
                    )
                ]
            )
        stations = config.stations
        placed: list[tuple[Kind, Pose]] = [
            (Kind.GENERATOR, Pose(x, y, math.pi / 2))
            for x, y in stations.placed(stations.generators)
        ]
        placed += [
            (Kind.SINK, Pose(x, y, -math.pi / 2)) for x, y in stations.placed(stations.sinks)
        ]
        low, high = fleet.spawn_min, fleet.spawn_max
        for _ in range(fleet.count):
            x, y = rng.uniform(low, high)
            placed.append((Kind.TRANSPORTER, Pose(x, y, rng.uniform(-math.pi, math.pi))))
        roster = tuple(range(1, len(placed) + 1))
        named = strategy_class(config.strategy.name)
        goal = setup.layer(GOAL)
        strategy = setup.layer(STRATEGY, default=named)
        group_activity = setup.layer(GROUP_ACTIVITY)
        task = setup.layer(TASK)
        action = setup.layer(ACTION)
        # What results.json calls the strategy: its name, or the class [layers] put instead.
        strategy_label = (
            config.strategy.name
            if strategy is named
            else f"{strategy.__module__}:{strategy.__qualname__}"
        )
        robots = []
        groups: dict[str, list[int]] = {kind.name.title(): [] for kind in Kind}
        for at, (robot_id, (kind, pose)) in enumerate(zip(roster, placed, strict=True)):
            params = Params(
                kind=kind,
                peers=Peers(roster, at),
                world=setup.world,
                speed=fleet.speed,
                deceleration=fleet.deceleration,
                min_speed=fleet.min_speed,
                handover_time=fleet.handover_time,
                range=config.strategy.range,
                search_step=config.strategy.search_step,
                retry_interval=config.strategy.retry_interval,
                search_growth=config.strategy.search_growth,
                seed=int(rng.integers(2**63)),
                timeout=config.messaging.timeout,
                retries=config.messaging.retries,
                patience=config.messaging.patience,
                sink_search=config.strategy.sink_search,
                reach=math.inf if reach is None else reach,
            )
            setup.environment.add_robot(robot_id, pose, mobile=params.mobile, top_speed=fleet.speed)
            groups[kind.name.title()].append(robot_id)
            if not setup.holds(robot_id):
                continue  # another process runs it: its place and its seed are drawn all the same
            middleware = SimulatedMiddleware(
                setup.environment,
                robot_id,
                setup.clock,
                turn_rate=fleet.turn_rate,
                speed_profile=params.empty(),
            )
            hands = SimulatedHands(setup.environment, robot_id, setup.clock, reach=_REACH)
            layers: list[Layer] = [
                goal(params),
                strategy(params),
                group_activity(params),
                task(params),
                action(params, middleware, hands),
            ]
            robots.append(setup.robot(robot_id, layers, messages=MESSAGES))
        generators = stations.placed(stations.generators)
        sinks = stations.placed(stations.sinks)
        on_lines = LineShare(groups["Transporter"], segments(generators, sinks), generators + sinks)
        return Mission(
            robots,
            config.mission.buckets,
            groups,
            extra=lambda: {"strategy": strategy_label},
            measures={"line_share": on_lines},
            snapshot_exchanges=THESIS_SNAPSHOTS,
            scene=brigade_scene(generators, sinks),
        )
