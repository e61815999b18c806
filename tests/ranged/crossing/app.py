"""A fast robot crosses a line of beacons, back and forth: a test app with an interaction range.

Beacons stand in a row along a long, thin world and call out every half second to
whoever is within range; the runner drives from one end to the other and back, far
faster than anything else, asking who is near and calling out as it goes, and each
beacon that hears it answers. Each leg ends with an item made and retired where it
ends: the objective (``Items``) is done after ``legs`` legs. Split across workers by
region, the runner crosses every worker's strip: which workers depend on which
changes all the time, and the results must not.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass
from typing import Final

from cas_async import ConstantSpeed, Hands, Layer, Message, Middleware, Pose
from cas_async.scenario import Items, LayerSlot, Mission, SimulationSetup, setting
from cas_async.sim import SimulatedHands, SimulatedMiddleware


class Beat(Message):
    """A beacon calls out (to those in range)."""

    k: int


class Ping(Message):
    """The runner calls out: its leg, and how many robots it sees around it."""

    leg: int
    near: int


class Pong(Message):
    """A beacon answers the runner (by then it may be out of range: the answer is lost)."""

    beats: int


MESSAGES: tuple[type[Message], ...] = (Beat, Ping, Pong)


class Beacon(Layer):
    """Stands still, calls out every ``period``, answers every Ping ``answer_after`` later."""

    def __init__(self, period: float, answer_after: float) -> None:
        self.period = period
        self.answer_after = answer_after
        self.beats = 0
        self.heard: list[int] = []
        self.asked: list[int] = []

    async def inner_process(self) -> None:
        if self.wake_due("beat") is None:
            self.wake_after(self.period, "beat")

    async def on_timer(self, key: Hashable) -> None:
        if key == "beat":
            self.beats += 1
            self.broadcast(Beat(self.beats))
        elif self.asked:  # the runner may be out of range by now: the answer is lost
            self.send(self.asked.pop(0), Pong(self.beats))

    async def handle_msg(self, msg: Message) -> None:
        match msg:
            case Ping():
                self.heard.append(msg.robot_id)
                self.asked.append(msg.robot_id)
                self.wake_after(self.answer_after, ("answer", len(self.heard)))
            case Beat():
                self.heard.append(msg.robot_id)


class Runner(Layer):
    """Drives its legs end to end a step at a time; before each step looks around and calls out."""

    def __init__(
        self,
        middleware: Middleware,
        hands: Hands,
        ends: Sequence[tuple[float, float]],
        radius: float,
        stride: float,
    ) -> None:
        self.middleware = middleware
        self.hands = hands
        self.ends = list(ends)
        self.radius = radius
        self.stride = stride
        self.leg = 0
        self.answers = 0

    async def inner_process(self) -> None:
        if self.leg == 0 and self.wake_due("step") is None:
            self.wake_after(0.0, "step")

    async def on_timer(self, key: Hashable) -> None:
        near = await self.middleware.robots_within(self.radius)
        self.broadcast(Ping(self.leg, len(near)))
        here = self.middleware.pose()
        x, y = self.ends[self.leg]
        gap = math.hypot(x - here.x, y - here.y)
        if gap > self.stride:  # a stride towards the end of the leg
            share = self.stride / gap
            x, y = here.x + share * (x - here.x), here.y + share * (y - here.y)
        await self.middleware.move_to(x, y)
        if (x, y) == self.ends[self.leg]:
            await self.hands.retire_item(await self.hands.create_item())
            self.leg += 1
        if self.leg < len(self.ends):
            self.wake_after(0.0, "step")

    async def handle_msg(self, msg: Message) -> None:
        match msg:
            case Pong():
                self.answers += 1


BEACON: Final = LayerSlot("beacon", Beacon, Beacon)


@dataclass(frozen=True)
class Line:
    beacons: int = setting(12, ge=2, le=200, doc="beacons in a row")
    period: float = setting(0.5, gt=0, doc="seconds between two calls of a beacon")
    speed: float = setting(20.0, gt=0, doc="the runner's speed, units per second")
    legs: int = setting(3, ge=1, doc="legs the runner drives, end to end")
    answer_after: float = setting(0.0, ge=0, doc="seconds a beacon waits to answer a Ping")
    look: float = setting(0.0, ge=0, doc="how far the runner looks around (0: the range)")


@dataclass(frozen=True)
class CrossingConfig:
    line: Line = setting(default_factory=Line)


class CrossingApp:
    name = "Crossing"
    item_name = "leg"
    config_type = CrossingConfig
    messages: Sequence[type[Message]] = MESSAGES

    def robots(self, config: CrossingConfig) -> dict[str, int]:
        return {"line.beacons": config.line.beacons + 1}

    def check(self, config: CrossingConfig, world: tuple[float, float]) -> None:
        return None

    def build(self, setup: SimulationSetup[CrossingConfig]) -> Mission:
        line = setup.config.line
        width, height = setup.world
        reach = setup.environment.interaction_range or math.hypot(width, height)
        robots = []
        step = width / line.beacons
        for robot_id in range(1, line.beacons + 1):
            x = step * (robot_id - 0.5)
            y = float(setup.rng.uniform(0.2 * height, 0.8 * height))
            setup.environment.add_robot(robot_id, Pose(x, y), mobile=False)
            if setup.holds(robot_id):
                beacon = setup.layer(BEACON)(line.period, line.answer_after)
                robots.append(setup.robot(robot_id, [beacon], messages=MESSAGES))
        runner_id = line.beacons + 1
        start = (1.0, height / 2)
        setup.environment.add_robot(runner_id, Pose(*start), top_speed=line.speed)
        if setup.holds(runner_id):
            middleware = SimulatedMiddleware(
                setup.environment,
                runner_id,
                setup.clock,
                turn_rate=math.inf,
                speed_profile=ConstantSpeed(line.speed),
            )
            hands = SimulatedHands(setup.environment, runner_id, setup.clock)
            far = (width - 1.0, height / 2)
            ends = [far if leg % 2 == 0 else start for leg in range(line.legs)]
            look = line.look or reach
            runner = Runner(middleware, hands, ends, look, stride=line.speed / 4)
            robots.append(setup.robot(runner_id, [runner], messages=MESSAGES))
        return Mission(robots, objective=Items(line.legs, noun="leg"))


app = CrossingApp()
