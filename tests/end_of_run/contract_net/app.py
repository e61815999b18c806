"""Contract-net task allocation, a test app (tests/test_end_of_run.py) on the public API.

Robot 1 is also the manager: it announces every task, collects bids for
``bid_window`` s, and awards each task to the lowest bid (plus a penalty per task
already awarded). A contractor drives to each task it won and does it (its robotic
layer creates and retires an item there: the ready-made, distributable ``Items``
objective counts it), then tells the manager. Once every task is done the manager
says ``Finished``; the top layer's termination_condition() holds then, as the
tutorial's Plan does once it arrived.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Final

from cas_async import ConstantSpeed, Finite, Hands, Layer, Message, Middleware, Pose, RobotId
from cas_async.scenario import Items, LayerSlot, Mission, SimulationSetup, setting
from cas_async.sim import SimulatedHands, SimulatedMiddleware

Coordinate = Annotated[float, Finite]
MANAGER: Final = 1


class Announce(Message):
    task: int
    x: Coordinate
    y: Coordinate


class Bid(Message):
    task: int
    cost: Coordinate


class Award(Message):
    task: int
    x: Coordinate
    y: Coordinate


class Done(Message):
    task: int


class Finished(Message):
    """Every task is done."""


class DoTask(Message):
    x: Coordinate
    y: Coordinate


class TaskDone(Message):
    pass


MESSAGES: tuple[type[Message], ...] = (Announce, Bid, Award, Done, Finished, DoTask, TaskDone)
Point = tuple[float, float]


class Contract(Layer):
    """Bids for tasks, does the ones it wins; robot 1 also manages the auction."""

    def __init__(
        self, home: Point, tasks: Sequence[Point], bid_window: float, stop_when_done: bool = True
    ) -> None:
        self.here = home
        self.stop_when_done = stop_when_done
        self.tasks = list(tasks)  # known to the manager only; contractors learn them by Announce
        self.bid_window = bid_window
        self.bids: dict[int, dict[RobotId, float]] = {}
        self.queue: list[tuple[int, Point]] = []
        self.working = False
        self.done: set[int] = set()
        self.finished = False

    @property
    def manager(self) -> bool:
        return self.robot_id == MANAGER

    async def inner_process(self) -> None:
        if self.manager and not self.bids:  # at start: announce every task, bid for them too
            for task, (x, y) in enumerate(self.tasks):
                self.bids[task] = {self.robot_id: math.dist(self.here, (x, y))}
                self.broadcast(Announce(task, x, y))
            self.wake_after(self.bid_window, "award")

    async def handle_msg(self, msg: Message) -> None:
        match msg:
            case Announce(task=task, x=x, y=y):
                self.send(msg.robot_id, Bid(task, self.cost(math.dist(self.here, (x, y)))))
            case Bid(task=task, cost=cost) if self.manager:
                self.bids[task][msg.robot_id] = cost
            case Award(task=task, x=x, y=y):
                self._won(task, (x, y))
            case Done(task=task) if self.manager:
                self._task_done(task)
            case Finished():
                self.finished = True

    async def on_timer(self, key: Hashable) -> None:
        if key == "award":
            load: dict[RobotId, int] = {}
            for task, bids in sorted(self.bids.items()):
                winner = min(bids, key=lambda r: (bids[r] + 10.0 * load.get(r, 0), r))
                load[winner] = load.get(winner, 0) + 1
                if winner == self.robot_id:
                    self._won(task, self.tasks[task])
                else:
                    self.send(winner, Award(task, *self.tasks[task]))
        elif key == "work" and self.queue and not self.working:
            task, (x, y) = self.queue.pop(0)
            self.working = True
            await self.request_down(DoTask(x, y), reply=TaskDone, timeout=math.inf)
            self.working = False
            self.here = (x, y)
            if self.manager:
                self._task_done(task)
            else:
                self.send(MANAGER, Done(task))
            if self.queue:
                self.wake_after(0.0, "work")

    def cost(self, distance: float) -> float:
        """What this robot bids for a task ``distance`` away (a policy may change it)."""
        return distance

    def _won(self, task: int, at: Point) -> None:
        self.queue.append((task, at))
        if not self.working and self.wake_due("work") is None:
            self.wake_after(0.0, "work")

    def _task_done(self, task: int) -> None:
        self.done.add(task)
        if len(self.done) == len(self.tasks):
            self.finished = True
            self.broadcast(Finished())

    def termination_condition(self) -> bool:
        return self.stop_when_done and self.finished


class Work(Layer):
    """The robotic layer: drives to a task and does it (an item created and retired there)."""

    def __init__(self, middleware: Middleware, hands: Hands) -> None:
        self.middleware = middleware
        self.hands = hands

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        match msg:
            case DoTask(x=x, y=y):
                await self.middleware.move_to(x, y)
                await self.hands.retire_item(await self.hands.create_item())
                return TaskDone()
        return None


class TasksDone(Items):
    verb = "done"


CONTRACT: Final = LayerSlot("contract", Contract, Contract)
WORK: Final = LayerSlot("work", Work, Work)


@dataclass(frozen=True)
class Robots:
    count: int = setting(3, ge=1, doc="robots; robot 1 is also the manager")
    speed: float = setting(1.0, gt=0, doc="m/s")


@dataclass(frozen=True)
class Tasks:
    count: int = setting(5, ge=1, doc="tasks to allocate and do")
    bid_window: float = setting(0.5, gt=0, doc="seconds the manager collects bids")
    stop_when_done: bool = setting(True, doc="the top layer stops once every task is done")


@dataclass(frozen=True)
class ContractConfig:
    robots: Robots = setting(default_factory=Robots)
    tasks: Tasks = setting(default_factory=Tasks)


class ContractApp:
    name = "Contract net"
    item_name = "task"
    config_type = ContractConfig
    stack: Sequence[LayerSlot[Any]] = (CONTRACT, WORK)
    messages: Sequence[type[Message]] = MESSAGES

    def robots(self, config: ContractConfig) -> dict[str, int]:
        return {"robots.count": config.robots.count}

    def check(self, config: ContractConfig, world: tuple[float, float]) -> None:
        return None

    def build(self, setup: SimulationSetup[ContractConfig]) -> Mission:
        width, height = setup.world
        cfg = setup.config
        tasks = [
            (float(setup.rng.uniform(0, width)), float(setup.rng.uniform(0, height)))
            for _ in range(cfg.tasks.count)
        ]
        contract, work = setup.layer(CONTRACT), setup.layer(WORK)
        robots = []
        for robot_id in range(1, cfg.robots.count + 1):
            home = (float(setup.rng.uniform(0, width)), float(setup.rng.uniform(0, height)))
            setup.environment.add_robot(robot_id, Pose(*home, 0.0))
            middleware = SimulatedMiddleware(
                setup.environment,
                robot_id,
                setup.clock,
                turn_rate=math.inf,
                speed_profile=ConstantSpeed(cfg.robots.speed),
            )
            hands = SimulatedHands(setup.environment, robot_id, setup.clock)
            top = contract(home, tasks, cfg.tasks.bid_window, cfg.tasks.stop_when_done)
            layers: list[Layer] = [top, work(middleware, hands)]
            robots.append(setup.robot(robot_id, layers, messages=MESSAGES))
        return Mission(robots, objective=TasksDone(cfg.tasks.count, noun="task"))


app = ContractApp()
