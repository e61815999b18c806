"""The five Fire Brigade layers together, in small swarms placed by hand, on virtual time.

Each test places a few robots exactly (not through the scenario runner), runs them
on a ``VirtualClock`` over a ``MemoryTransport``, and reads what happened from the
Environment: the item ledger (who held which bucket when) and every motion started
(with the speed profile it followed). Times are compared with the estimate module.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass, replace
from types import TracebackType
from typing import Any, TypeVar

import pytest

import cas_async
from apps.fire_brigade import MESSAGES, RandomStrategy, SoloStrategy, Strategy, TimeStrategy
from apps.fire_brigade.action import Action
from apps.fire_brigade.base import ACTION, GROUP, STRATEGY, Params
from apps.fire_brigade.estimate import carrying_time, distance, meeting_point
from apps.fire_brigade.goal import Goal
from apps.fire_brigade.group_activity import GroupActivity
from apps.fire_brigade.messages import (
    Destination,
    Kind,
    PartnerAnswer,
    RequestPartner,
    RequestRobotsInRange,
)
from apps.fire_brigade.strategy import SearchView
from apps.fire_brigade.task import Task
from cas_async import (
    ConstantSpeed,
    Decelerating,
    Layer,
    LayerError,
    MemoryTransport,
    Message,
    MsgType,
    Pose,
    Robot,
    Swarm,
    VirtualClock,
)
from cas_async.sim import (
    Environment,
    ItemEvent,
    ItemEventKind,
    Motion,
    SimulatedHands,
    SimulatedMiddleware,
)

T = TypeVar("T")

GENERATOR, SINK, TRANSPORTER = Kind.GENERATOR, Kind.SINK, Kind.TRANSPORTER
NORTH, SOUTH, EAST, WEST = math.pi / 2, -math.pi / 2, 0.0, math.pi
CREATED, TRANSFERRED, RETIRED = (
    ItemEventKind.CREATED,
    ItemEventKind.TRANSFERRED,
    ItemEventKind.RETIRED,
)

SPEED, DECELERATION, MIN_SPEED, HANDOVER = 5.0, 1.0, 1.0, 0.5
# How a transporter moves from the moment it takes a bucket.
FATIGUE = Decelerating(SPEED, DECELERATION, MIN_SPEED)


def play(main: Callable[[], Coroutine[Any, Any, T]]) -> T:
    return cas_async.run(main(), virtual=True)


def _params(kind: Kind, peers: tuple[int, ...], *, seed: int) -> Params:
    """A robot's constants in these tests (a 10 x 10 world, the speeds above)."""
    return Params(
        kind=kind,
        peers=peers,
        world=(10.0, 10.0),
        speed=SPEED,
        deceleration=DECELERATION,
        min_speed=MIN_SPEED,
        handover_time=HANDOVER,
        range=5.0,
        search_step=1.0,
        retry_interval=1.0,
        search_growth=2.0,
        seed=seed,
    )


@dataclass(frozen=True)
class Spot:
    """Where a robot of a hand-built swarm stands at the start, and what it is."""

    robot: int
    kind: Kind
    x: float
    y: float
    heading: float = 0.0


class Motions(Environment):
    """An Environment that remembers every motion started, with its speed profile."""

    def __init__(self) -> None:
        super().__init__()
        self.started: list[tuple[int, float, Motion]] = []

    def start_motion(self, robot_id: int, motion: Motion, start_time: float) -> None:
        super().start_motion(robot_id, motion, start_time)
        self.started.append((robot_id, start_time, motion))

    def translations(
        self, robot: int, after: float = -math.inf, before: float = math.inf
    ) -> list[Motion]:
        """The robot's moves that translated, started within ``[after, before)``."""
        return [
            motion
            for robot_id, start, motion in self.started
            if robot_id == robot and motion.length > 0 and after <= start < before
        ]


class Recording(TimeStrategy):
    """The time strategy, keeping each search's radius and view and each answer it got."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.radii: list[float] = []
        self.views: list[SearchView] = []
        self.answers: list[tuple[int, MsgType]] = []  # (who answered, how)

    def choose(self, view: SearchView) -> list[int]:
        self.radii.append(self.radius)
        self.views.append(view)
        return super().choose(view)

    async def handle_msg(self, msg: Message) -> None:
        if isinstance(msg, PartnerAnswer):
            self.answers.append((msg.robot_id, msg.msg_type))
        await super().handle_msg(msg)


class Asker(Layer):
    """A probe robot's Strategy-level layer: asks robots for a partnership."""

    async def ask(self, robot: int, kind: Kind) -> MsgType:
        """How ``robot`` answers a giver of ``kind`` (ACCEPT or DENY)."""
        request = RequestPartner(0.0, 0.0, kind, bucket=99, to=Destination(2, 5.0, 9.0))
        answer = await self.request(robot, request, reply=PartnerAnswer)
        return answer.msg_type


class Brigade:
    """A hand-built Fire Brigade: robots placed exactly, one clock, one in-memory network.

    Use it as ``async with Brigade(...) as b:``, then ``await b.until(...)``; leaving
    the block stops every robot.
    """

    def __init__(
        self,
        spots: Sequence[Spot],
        *,
        strategy: type[Strategy] = Recording,
        turn_rate: float = math.pi,
        **changes: Any,
    ) -> None:
        self.env = Motions()
        self.clock = VirtualClock()
        self.transport = MemoryTransport()
        self.events: list[ItemEvent] = []
        # Where giver and receiver stood at each hand-over (the Environment keeps only
        # each robot's current motion, so past poses are taken when they happen).
        self.handovers: list[tuple[ItemEvent, Pose, Pose]] = []
        self.env.items.subscribe(self._on_item)
        self._changed = asyncio.Event()
        self.others: list[Robot] = []  # robots outside the roster (probes)
        roster = tuple(spot.robot for spot in spots)
        self.robots: dict[int, Robot] = {}
        for spot in spots:
            peers = tuple(r for r in roster if r != spot.robot)
            params = replace(_params(spot.kind, peers, seed=spot.robot), **changes)
            self.env.add_robot(spot.robot, Pose(spot.x, spot.y, spot.heading), mobile=params.mobile)
            middleware = SimulatedMiddleware(
                self.env,
                spot.robot,
                self.clock,
                turn_rate=turn_rate,
                speed_profile=ConstantSpeed(params.speed),
            )
            hands = SimulatedHands(self.env, spot.robot, self.clock)
            layers = [
                Goal(params),
                strategy(params),
                GroupActivity(params),
                Task(params),
                Action(params, middleware, hands),
            ]
            self.robots[spot.robot] = Robot(
                spot.robot, layers, transport=self.transport, clock=self.clock, messages=MESSAGES
            )

    def add_probe(self, robot_id: int) -> Asker:
        """A robot outside the roster (nobody asks it anything) that can ask partners."""
        asker = Asker()
        layers = [Layer(), asker, Layer(), Layer(), Layer()]  # the same stack shape
        self.others.append(
            Robot(robot_id, layers, transport=self.transport, clock=self.clock, messages=MESSAGES)
        )
        self.env.add_robot(robot_id, Pose(0.0, 0.0), mobile=False)
        return asker

    def layer(self, robot: int, level: int) -> Any:
        return self.robots[robot].layers[level]

    def middleware(self, robot: int) -> SimulatedMiddleware:
        middleware = self.layer(robot, ACTION).middleware
        assert isinstance(middleware, SimulatedMiddleware)
        return middleware

    def path(self, item: int) -> list[int]:
        """The robots that held ``item``, in order."""
        history = self.env.items.history(item)
        return [history[0].robot] + [e.receiver for e in history if e.kind is TRANSFERRED]  # type: ignore[misc]

    def when(self, kind: ItemEventKind, item: int, robot: int | None = None) -> float:
        """When ``item`` was created, retired, or handed to ``robot``."""
        for event in self.env.items.history(item):
            if event.kind is kind and (robot is None or robot in (event.robot, event.receiver)):
                return event.t
        raise AssertionError(f"no {kind.name} event of item {item} for robot {robot}")

    @property
    def delivered(self) -> int:
        return self.env.items.retired

    def _on_item(self, event: ItemEvent) -> None:
        self.events.append(event)
        if event.kind is TRANSFERRED:
            assert event.receiver is not None
            giver = self.env.pose_at(event.robot, event.t)
            self.handovers.append((event, giver, self.env.pose_at(event.receiver, event.t)))
        self._changed.set()

    async def __aenter__(self) -> Brigade:
        self._swarm = Swarm([*self.robots.values(), *self.others])
        await self._swarm.__aenter__()
        self._running = asyncio.ensure_future(self._swarm.run())
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        running = self._running
        running.cancel()
        with contextlib.suppress(asyncio.CancelledError, LayerError):
            await running
        await self._swarm.__aexit__(exc_type, exc, tb)
        # A robot that failed while the test was not in until() still fails the test.
        if exc is None and not running.cancelled() and running.exception() is not None:
            raise running.exception()  # type: ignore[misc]

    async def until(self, condition: Callable[[], bool], *, within: float) -> None:
        """Returns once ``condition()`` holds after an item event; fails after ``within`` s.

        Raises:
            LayerError: a robot failed meanwhile.
            AssertionError: ``within`` simulated seconds passed first.
        """
        deadline = self.clock.now() + within
        while not condition():
            self._changed.clear()
            changed = asyncio.ensure_future(self._changed.wait())
            timer = asyncio.ensure_future(self.clock.sleep_until(deadline))
            try:
                done, _ = await asyncio.wait(
                    {changed, timer, self._running}, return_when=asyncio.FIRST_COMPLETED
                )
            finally:
                changed.cancel()
                timer.cancel()
            if self._running in done:
                self._running.result()  # raises the LayerError
                raise AssertionError("the swarm stopped")
            if timer in done and not condition():
                raise AssertionError(f"not done within {within} s; item events: {self.events}")


# A Generator, a Sink 8 north of it, and a Transporter 1 south of the Generator, all
# on the line x = 5 and facing along it, so nobody turns before the first delivery:
# until then every time is a translation time plus hand-overs.
LINE = [
    Spot(1, GENERATOR, 5.0, 1.0, NORTH),
    Spot(2, SINK, 5.0, 9.0, SOUTH),
    Spot(3, TRANSPORTER, 5.0, 0.0, NORTH),
]


# -- one transporter --------------------------------------------------------------------


def test_a_robots_two_profiles_are_made_once_and_follow_its_speeds() -> None:
    # Layers ask for them on every estimate: one object each keeps the phases a
    # profile works out; replace() (a sweep's other speed) makes new ones.
    params = _params(Kind.TRANSPORTER, (2,), seed=1)
    assert params.empty() is params.empty()
    assert params.empty() == ConstantSpeed(SPEED)
    assert params.carrying() is params.carrying()
    assert params.carrying() == Decelerating(SPEED, DECELERATION, MIN_SPEED)
    assert params.carrying(1.5) == Decelerating(1.5, DECELERATION, min(MIN_SPEED, 1.5))
    slower = replace(params, speed=SPEED / 2)
    assert slower.empty() == ConstantSpeed(SPEED / 2)
    assert slower.carrying() == Decelerating(SPEED / 2, DECELERATION, min(MIN_SPEED, SPEED / 2))
    assert slower == replace(slower)


@pytest.mark.parametrize(
    ("search_range", "legs"),
    [
        # The Sink (8 away) is beyond range 5: three steps of 1, then it is 5 away.
        pytest.param(5.0, [1.0, 1.0, 1.0, 5.0], id="steps-then-sink"),
        pytest.param(2.0, [1.0] * 6 + [2.0], id="short-range"),
        pytest.param(8.0, [8.0], id="sink-in-range-at-once"),
    ],
)
def test_a_transporter_carries_the_bucket_to_the_sink(
    search_range: float, legs: list[float]
) -> None:
    async def main() -> Brigade:
        async with Brigade(LINE, range=search_range) as b:
            await b.until(lambda: b.delivered == 1, within=30.0)
        return b

    b = play(main)
    assert b.path(1) == [1, 3, 2]  # Generator -> Transporter -> Sink
    assert b.events[-1].kind is RETIRED
    picked, dropped = b.when(TRANSFERRED, 1, 3), b.when(RETIRED, 1)
    # 1 unit at full speed to the Generator, then the hand-over.
    assert picked == pytest.approx(1.0 / SPEED + HANDOVER)
    # Carrying 8 units from fresh: 5t - t²/2 = 8 gives t = 2 s; then the hand-over.
    assert carrying_time(8.0, FATIGUE) == pytest.approx(2.0)
    assert dropped - picked == pytest.approx(carrying_time(8.0, FATIGUE) + HANDOVER)
    carried = b.env.translations(3, after=picked, before=dropped)
    assert [leg.length for leg in carried] == pytest.approx(legs)
    assert b.env.items.held_by(3) == ()


def test_a_transporter_slows_while_carrying_and_is_fresh_after() -> None:
    async def main() -> Brigade:
        async with Brigade(LINE) as b:
            await b.until(lambda: b.delivered == 2, within=60.0)
        return b

    b = play(main)
    assert b.path(1) == b.path(2) == [1, 3, 2]
    first = b.env.translations(3, before=b.when(TRANSFERRED, 1, 3))
    carrying = b.env.translations(3, after=b.when(TRANSFERRED, 1, 3), before=b.when(RETIRED, 1))
    back = b.env.translations(3, after=b.when(RETIRED, 1), before=b.when(TRANSFERRED, 2, 3))
    again = b.env.translations(3, after=b.when(TRANSFERRED, 2, 3), before=b.when(RETIRED, 2))
    assert [m.profile for m in first] == [ConstantSpeed(SPEED)]
    assert [m.profile for m in back] == [ConstantSpeed(SPEED)] * len(back)
    assert sum(m.length for m in back) == pytest.approx(8.0)
    for legs in (carrying, again):
        # Fatigue carries over from leg to leg: each starts at the speed the last ended at.
        assert all(isinstance(m.profile, Decelerating) for m in legs)
        assert legs[0].profile == FATIGUE  # fresh at the pick-up
        elapsed = 0.0
        for leg in legs:
            assert leg.profile.speed_at(0.0) == pytest.approx(  # type: ignore[union-attr]
                max(MIN_SPEED, SPEED - DECELERATION * elapsed)
            )
            elapsed += leg.translation_time
        assert elapsed == pytest.approx(carrying_time(8.0, FATIGUE))
    assert b.middleware(3).speed_profile == ConstantSpeed(SPEED)


# A Sink 20 away from the Generator: a carrier slows to its floor after 4 s (12 units),
# then crawls the last 8 at the minimum speed.
LONG = [
    Spot(1, GENERATOR, 1.0, 0.0, NORTH),
    Spot(2, SINK, 1.0, 20.0, SOUTH),
    Spot(3, TRANSPORTER, 1.0, -1.0, NORTH),
]


def test_fatigue_reaches_the_minimum_speed_on_a_long_carry() -> None:
    async def main() -> Brigade:
        async with Brigade(LONG, world=(10.0, 20.0)) as b:
            await b.until(lambda: b.delivered == 1, within=60.0)
        return b

    b = play(main)
    assert b.path(1) == [1, 3, 2]
    legs = b.env.translations(3, after=b.when(TRANSFERRED, 1, 3), before=b.when(RETIRED, 1))
    assert sum(leg.length for leg in legs) == pytest.approx(20.0)
    assert sum(leg.translation_time for leg in legs) == pytest.approx(4.0 + 8.0 / MIN_SPEED)
    assert carrying_time(20.0, FATIGUE) == pytest.approx(4.0 + 8.0 / MIN_SPEED)
    assert legs[-1].profile == Decelerating(MIN_SPEED, DECELERATION, MIN_SPEED)


def test_the_destination_is_the_sink_nearest_the_generator() -> None:
    spots = [
        Spot(1, GENERATOR, 8.0, 1.0, NORTH),
        Spot(2, SINK, 1.0, 9.0, SOUTH),  # 10.6 away
        Spot(3, SINK, 9.0, 9.0, SOUTH),  # 8.06 away
        Spot(4, TRANSPORTER, 8.0, 0.0, NORTH),
    ]

    async def main() -> Brigade:
        async with Brigade(spots) as b:
            await b.until(lambda: b.delivered == 1, within=30.0)
        return b

    b = play(main)
    assert b.path(1) == [1, 4, 3]
    assert b.layer(1, 0).sinks == {2: (1.0, 9.0), 3: (9.0, 9.0)}


def test_a_generator_with_nobody_in_range_widens_its_search() -> None:
    # Range 3 around the Generator holds nobody who can take a bucket; 6 neither; 12 does.
    spots = [
        Spot(1, GENERATOR, 5.0, 1.0, NORTH),
        Spot(2, SINK, 5.0, 9.0, SOUTH),
        Spot(3, TRANSPORTER, 9.5, 9.5, math.atan2(1.0 - 9.5, 5.0 - 9.5)),  # facing it
    ]

    async def main() -> Brigade:
        async with Brigade(spots, range=3.0, retry_interval=1.0, search_growth=2.0) as b:
            await b.until(lambda: b.env.items.held_by(3) != (), within=30.0)
        return b

    b = play(main)
    generator = b.layer(1, STRATEGY)
    assert generator.radii[:3] == [3.0, 6.0, 12.0]
    assert [view.candidates for view in generator.views[:2]] == [(), ()]
    gap = distance((5.0, 1.0), (9.5, 9.5))
    assert b.when(TRANSFERRED, 1, 3) == pytest.approx(2 * 1.0 + gap / SPEED + HANDOVER)


# -- partners -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("strategy", "path"),
    [
        # Tired after the pick-up, the carrier hands over to the fresh Transporter ahead.
        pytest.param(TimeStrategy, [1, 3, 4, 2], id="time-relays"),
        pytest.param(SoloStrategy, [1, 3, 2], id="solo-carries"),
    ],
)
def test_a_carrier_hands_over_to_a_fresher_partner_ahead(
    strategy: type[Strategy], path: list[int]
) -> None:
    spots = [*LINE, Spot(4, TRANSPORTER, 5.0, 5.0, SOUTH)]

    async def main() -> Brigade:
        async with Brigade(spots, strategy=strategy) as b:
            await b.until(lambda: b.delivered == 1, within=30.0)
        return b

    b = play(main)
    assert b.path(1) == path
    if strategy is TimeStrategy:
        # They met where equation 3 puts them: both driving at once, one tired, one fresh.
        expected = meeting_point((5.0, 1.0), (5.0, 5.0), FATIGUE, ConstantSpeed(SPEED))
        [relay] = [(g, r) for e, g, r in b.handovers if (e.robot, e.receiver) == (3, 4)]
        assert (relay[1].x, relay[1].y) == pytest.approx(expected)
        assert (relay[0].x, relay[0].y) == (relay[1].x, relay[1].y)


def test_one_request_at_a_time_so_one_partnership_per_bucket() -> None:
    # Two idle Transporters equally near the Generator: only the first asked (the lower
    # id, on a tie) partners; the other never hears of this bucket.
    spots = [
        Spot(1, GENERATOR, 5.0, 1.0, NORTH),
        Spot(2, SINK, 5.0, 9.0, SOUTH),
        Spot(3, TRANSPORTER, 4.0, 1.0, EAST),
        Spot(4, TRANSPORTER, 6.0, 1.0, WEST),
    ]
    seen: dict[str, object] = {}

    async def main() -> Brigade:
        async with Brigade(spots) as b:

            def at_first_handover() -> bool:
                if b.env.items.transfers and not seen:
                    seen["asked"] = b.layer(1, STRATEGY).counters.external_by_type[RequestPartner]
                    seen["partnered"] = [
                        robot for robot in (3, 4) if b.layer(robot, GROUP).partnerships
                    ]
                    seen["moved"] = {robot: len(b.env.translations(robot)) for robot in (3, 4)}
                return bool(seen)

            await b.until(at_first_handover, within=10.0)
        return b

    b = play(main)
    assert b.path(1)[:2] == [1, 3]
    assert seen == {"asked": 1, "partnered": [3], "moved": {3: 1, 4: 0}}
    assert b.layer(1, STRATEGY).answers[0] == (3, MsgType.ACCEPT)


def test_two_generators_race_for_one_transporter_and_one_is_refused() -> None:
    # Both Generators ask the one Transporter at the same instant: it takes one
    # bucket and refuses the other giver.
    spots = [
        Spot(1, GENERATOR, 4.0, 1.0, NORTH),
        Spot(2, GENERATOR, 6.0, 1.0, NORTH),
        Spot(3, SINK, 5.0, 9.0, SOUTH),
        Spot(4, TRANSPORTER, 5.0, 1.0, NORTH),
    ]

    async def main() -> Brigade:
        async with Brigade(spots) as b:
            await b.until(lambda: b.delivered == 1, within=30.0)
        return b

    b = play(main)
    first_answers = {g: b.layer(g, STRATEGY).answers[0] for g in (1, 2)}
    assert sorted(first_answers.values()) == [(4, MsgType.ACCEPT), (4, MsgType.DENY)]
    winner = next(g for g, (_, how) in first_answers.items() if how == MsgType.ACCEPT)
    first = b.events[[e.kind for e in b.events].index(TRANSFERRED)]
    assert (first.robot, first.receiver) == (winner, 4)
    # While the Transporter was busy, every later request of the other was refused too.
    loser = 3 - winner
    assert all(how == MsgType.DENY for _, how in b.layer(loser, STRATEGY).answers)
    assert b.layer(loser, STRATEGY).stations == {winner}  # it asked the other Generator too


def test_a_busy_transporter_refuses_partners_and_an_idle_one_accepts() -> None:
    spots = [*LINE, Spot(4, TRANSPORTER, 9.0, 9.0, WEST)]
    answers: dict[str, MsgType] = {}

    async def main() -> None:
        b = Brigade(spots, range=4.0)  # robot 4 is out of everyone's range until late
        asker = b.add_probe(9)
        async with b:
            await b.until(lambda: b.env.items.held_by(3) != (), within=10.0)
            await b.clock.sleep(0.1)  # carrying it north, alone
            answers["carrying"] = await asker.ask(3, TRANSPORTER)
            answers["generator"] = await asker.ask(1, TRANSPORTER)
            answers["sink, to a generator"] = await asker.ask(2, GENERATOR)
            answers["sink, to a transporter"] = await asker.ask(2, TRANSPORTER)
            answers["idle"] = await asker.ask(4, TRANSPORTER)
            answers["idle, now partnered"] = await asker.ask(4, GENERATOR)

    play(main)
    assert answers == {
        "carrying": MsgType.DENY,
        "generator": MsgType.DENY,
        "sink, to a generator": MsgType.DENY,  # two immobile robots cannot meet
        "sink, to a transporter": MsgType.ACCEPT,  # a Sink takes several at once
        "idle": MsgType.ACCEPT,
        "idle, now partnered": MsgType.DENY,
    }


def test_random_partners_still_deliver_and_replay_by_seed() -> None:
    spots = [
        Spot(1, GENERATOR, 4.0, 0.0, NORTH),
        Spot(2, SINK, 4.0, 9.0, SOUTH),
        *(Spot(3 + i, TRANSPORTER, 2.0 + i, 2.0 + i % 3 * 2.0, EAST) for i in range(5)),
    ]

    def run() -> list[list[int]]:
        async def main() -> Brigade:
            async with Brigade(spots, strategy=RandomStrategy) as b:
                await b.until(lambda: b.delivered == 3, within=120.0)
            return b

        b = play(main)
        return [b.path(item) for item in range(1, 4)]

    paths = run()
    assert paths == run()
    assert all(path[0] == 1 and path[-1] == 2 for path in paths)


def test_every_message_reaches_a_layer_that_expects_it(caplog: pytest.LogCaptureFixture) -> None:
    spots = [
        Spot(1, GENERATOR, 4.0, 0.0, NORTH),
        Spot(2, GENERATOR, 8.0, 0.0, NORTH),
        Spot(3, SINK, 4.0, 9.0, SOUTH),
        Spot(4, SINK, 8.0, 9.0, SOUTH),
        *(Spot(5 + i, TRANSPORTER, 3.0 + i, 1.0 + i % 4 * 2.0, NORTH) for i in range(6)),
    ]

    async def main() -> Brigade:
        async with Brigade(spots) as b:
            await b.until(lambda: b.delivered == 6, within=120.0)
        return b

    with caplog.at_level("WARNING", logger="cas_async"):
        b = play(main)
    assert [r.getMessage() for r in caplog.records] == []
    assert all(robot.dropped == {} for robot in b.robots.values())
    b.env.items.check()
    searches = sum(
        b.layer(robot, STRATEGY).counters.internal_by_type.get(RequestRobotsInRange, 0)
        for robot in b.robots
    )
    assert searches > 0


# -- found by review, fixed ------------------------------------------------------------------


@pytest.mark.parametrize(
    "changes",
    [
        pytest.param({"handover_time": 6.0, "world": (40.0, 40.0)}, id="long-handover"),
        pytest.param({"search_step": 30.0, "world": (40.0, 40.0)}, id="long-carry-leg"),
    ],
)
def test_actions_longer_than_five_seconds(changes: dict[str, Any]) -> None:
    spots = [
        Spot(1, GENERATOR, 5.0, 1.0, NORTH),
        Spot(2, SINK, 5.0, 39.0, SOUTH),
        Spot(3, TRANSPORTER, 5.0, 0.0, NORTH),
    ]

    async def main() -> None:
        async with Brigade(spots, **changes) as b:
            await b.until(lambda: b.delivered == 1, within=120.0)

    play(main)


def test_a_carrier_never_waits_for_a_generators_answer() -> None:
    # The tired carrier asks the Generator behind it (not yet known as a station) while
    # that Generator is between two retries of its own search.
    async def main() -> Brigade:
        async with Brigade(LONG, world=(10.0, 20.0)) as b:
            await b.until(lambda: b.delivered == 1, within=60.0)
        return b

    b = play(main)
    carried = b.when(RETIRED, 1) - b.when(TRANSFERRED, 1, 3)
    assert carried == pytest.approx(carrying_time(20.0, FATIGUE) + HANDOVER)
