"""Area coverage, a test app (tests/test_end_of_run.py) on the public API.

Written from docs/tutorial.md and docs/app-contract.md, public API only. Once every
cell is visited the robots stop moving and sending; `[explore] when_done` says how:
"quiet" (default: nothing more happens, no layer stops), "terminate" (Explore's
termination_condition() holds) or "stop" (Explore calls self.robot.stop()).
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Final

from cas_async import ConstantSpeed, Finite, Layer, Message, Middleware, Pose, RobotId
from cas_async.scenario import (
    LayerSlot,
    Mission,
    Objective,
    RunResult,
    ScenarioError,
    SimulationSetup,
    Tally,
    Watch,
    setting,
)
from cas_async.sim import Motion, SimulatedMiddleware

Coordinate = Annotated[float, Finite]


class Claim(Message):
    """The sender drives to cell ``cell``."""

    cell: int


class Visited(Message):
    """The sender stood in cell ``cell``."""

    cell: int


class DriveTo(Message):
    x: Coordinate
    y: Coordinate


class Arrived(Message):
    x: Coordinate
    y: Coordinate


MESSAGES: tuple[type[Message], ...] = (Claim, Visited, DriveTo, Arrived)


class Grid:
    """``cols`` x ``rows`` cells of ``size`` metres, numbered row by row."""

    def __init__(self, cols: int, rows: int, size: float) -> None:
        self.cols, self.rows, self.size = cols, rows, size

    def __len__(self) -> int:
        return self.cols * self.rows

    def centre(self, cell: int) -> tuple[float, float]:
        return ((cell % self.cols + 0.5) * self.size, (cell // self.cols + 0.5) * self.size)

    def cell_of(self, x: float, y: float) -> int | None:
        c, r = int(x // self.size), int(y // self.size)
        return r * self.cols + c if 0 <= c < self.cols and 0 <= r < self.rows else None


class Explore(Layer):
    """Claims the nearest cell nobody claimed, drives there, says it was visited; repeats."""

    def __init__(self, grid: Grid, home: tuple[float, float], when_done: str = "quiet") -> None:
        self.grid = grid
        self.when_done = when_done  # "quiet", "terminate" or "stop" (see Explore.done)
        self.here = home
        self.visited: set[int] = set()
        self.claimed: dict[int, RobotId] = {}
        self.driving = False

    def free(self) -> list[int]:
        return [c for c in range(len(self.grid)) if c not in self.visited and c not in self.claimed]

    async def inner_process(self) -> None:  # at start, and after each batch of messages
        if not self.driving and self.free() and self.wake_due("next") is None:
            self.wake_after(0.0, "next")

    async def handle_msg(self, msg: Message) -> None:
        match msg:
            case Claim(cell=cell):
                # two claims of one cell: the lower id keeps it
                self.claimed[cell] = min(self.claimed.get(cell, msg.robot_id), msg.robot_id)
            case Visited(cell=cell):
                self.visited.add(cell)
                self.done()

    def done(self) -> None:
        """Every cell visited: "stop" stops the robot; "quiet" and "terminate" do nothing more."""
        if len(self.visited) == len(self.grid) and self.when_done == "stop":
            self.robot.stop()

    def termination_condition(self) -> bool:
        # Only a "terminate" layer judges: the other modes never hold (the robot runs on, quiet).
        return self.when_done == "terminate" and len(self.visited) == len(self.grid)

    async def on_timer(self, key: Hashable) -> None:
        if key != "next" or self.driving:
            return
        free = self.free()
        if not free:
            return  # every cell visited or claimed: quiet (no timer, no message)
        cell = min(free, key=lambda c: (math.dist(self.here, self.grid.centre(c)), c))
        self.claimed[cell] = self.robot_id
        self.broadcast(Claim(cell))
        self.driving = True
        arrived = await self.request_down(
            DriveTo(*self.grid.centre(cell)), reply=Arrived, timeout=math.inf
        )
        self.driving = False
        self.here = (arrived.x, arrived.y)
        self.visited.add(cell)
        self.broadcast(Visited(cell))
        self.done()
        if self.free():
            self.wake_after(0.0, "next")


class Drive(Layer):
    def __init__(self, middleware: Middleware) -> None:
        self.middleware = middleware

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        match msg:
            case DriveTo(x=x, y=y):
                pose = await self.middleware.move_to(x, y)
                return Arrived(pose.x, pose.y)
        return None


class Covered(Objective):
    """Every cell had a robot standing in it; reads only the Environment's motions."""

    noun = "cell"
    verb = "visited"
    detail = "moving"
    kind = "coverage"
    distributable = True

    def __init__(self, grid: Grid) -> None:
        self.grid = grid
        self._visits: dict[int, float] = {}
        self._moving: set[RobotId] = set()
        self._watch: Watch | None = None
        self._done = False

    @property
    def target(self) -> int:
        return len(self.grid)

    def attach(self, watch: Watch) -> None:
        self._watch = watch
        watch.environment.watch_motions(self._moved)

    def _moved(self, robot: RobotId, motion: Motion, start: float) -> None:
        if self._watch is None or self._done:
            return
        if motion.duration > 0:
            self._moving.add(robot)
        else:
            self._moving.discard(robot)
            cell = self.grid.cell_of(motion.end.x, motion.end.y)
            if cell is not None:
                self._visits.setdefault(cell, start)
        self._watch.changed(start)
        if len(self._visits) == len(self.grid):
            self._done = True
            self._watch.completed(start)

    def progress(self) -> Tally:
        return Tally(len(self._visits), len(self._moving))

    def measure(self, result: RunResult, end: float) -> None:
        result.delivered = len(self._visits)
        result.delivery_times = sorted(self._visits.values())


EXPLORE: Final = LayerSlot("explore", Explore, Explore)
DRIVE: Final = LayerSlot("drive", Drive, Drive)


@dataclass(frozen=True)
class Robots:
    count: int = setting(6, ge=1, doc="robots")
    speed: float = setting(1.0, gt=0, doc="m/s")


@dataclass(frozen=True)
class Cells:
    cols: int = setting(6, ge=1, doc="columns")
    rows: int = setting(4, ge=1, doc="rows")
    size: float = setting(2.0, gt=0, doc="cell side, metres")


@dataclass(frozen=True)
class Done:
    when_done: str = setting(
        "quiet", doc='once every cell is visited: "quiet", "terminate", "stop"'
    )


@dataclass(frozen=True)
class CoverageConfig:
    robots: Robots = setting(default_factory=Robots)
    grid: Cells = setting(default_factory=Cells)
    explore: Done = setting(default_factory=Done)


class CoverageApp:
    name = "Coverage"
    item_name = "cell"
    config_type = CoverageConfig
    stack: Sequence[LayerSlot[Any]] = (EXPLORE, DRIVE)
    messages: Sequence[type[Message]] = MESSAGES

    def robots(self, config: CoverageConfig) -> dict[str, int]:
        return {"robots.count": config.robots.count}

    def check(self, config: CoverageConfig, world: tuple[float, float]) -> None:
        g = config.grid
        if g.cols * g.size > world[0] or g.rows * g.size > world[1]:
            raise ScenarioError([("grid", "the grid must fit in the world")])
        if config.explore.when_done not in ("quiet", "terminate", "stop"):
            raise ScenarioError([("explore.when_done", 'expected "quiet", "terminate" or "stop"')])

    def build(self, setup: SimulationSetup[CoverageConfig]) -> Mission:
        g = setup.config.grid
        grid = Grid(g.cols, g.rows, g.size)
        explore, drive = setup.layer(EXPLORE), setup.layer(DRIVE)
        robots = []
        for robot_id in range(1, setup.config.robots.count + 1):
            home = (float(setup.rng.uniform(0, g.cols * g.size)), 0.0)
            setup.environment.add_robot(robot_id, Pose(*home, 0.0))
            middleware = SimulatedMiddleware(
                setup.environment,
                robot_id,
                setup.clock,
                turn_rate=math.inf,
                speed_profile=ConstantSpeed(setup.config.robots.speed),
            )
            layers: list[Layer] = [
                explore(grid, home, setup.config.explore.when_done),
                drive(middleware),
            ]
            robots.append(setup.robot(robot_id, layers, messages=MESSAGES))
        return Mission(robots, objective=Covered(grid))


app = CoverageApp()
