"""The layer programming model: what a new user writes first, made to work as written.

Each section reproduces one sharp edge a new user hit (issue 15): mutual requests,
a periodic sender, a robot that leaves, untyped replies, unhelpful errors.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
import math
from collections.abc import Hashable

import pytest

import cas_async
from cas_async import (
    ConfigurationError,
    Layer,
    LayerError,
    MemoryTransport,
    Message,
    MsgType,
    RequestTimeout,
    Robot,
    RobotGone,
    RuleViolation,
    ScaledClock,
    Swarm,
    UdpTransport,
    UnexpectedReply,
    VirtualClock,
    message,
)


@message
class Ping(Message):
    n: int


@message
class Pong(Message):
    n: int


MESSAGES = (Ping, Pong)


def robot(robot_id: int, *layers: Layer, transport: object, clock: object) -> Robot:
    return Robot(robot_id, list(layers), transport=transport, clock=clock, messages=MESSAGES)  # type: ignore[arg-type]


# -- 1. two robots that ask each other at the same instant ---------------------------------


class Curious(Layer):
    """Asks ``others`` in turn from inner_process and answers on arrival (get_msg_reply)."""

    def __init__(self, others: list[int], rounds: int = 1) -> None:
        self.others = others
        self.rounds = rounds
        self.answers: list[tuple[int, float]] = []
        self.timeouts = 0

    async def inner_process(self) -> None:
        while self.rounds:
            self.rounds -= 1
            for other in self.others:
                try:
                    pong = await self.request(other, Ping(self.robot_id), reply=Pong, timeout=1.0)
                except RequestTimeout:
                    self.timeouts += 1
                else:
                    self.answers.append((pong.n, self.clock.now()))

    def get_msg_reply(self, msg: Message) -> Message | None:
        match msg:
            case Ping(n=n):
                return Pong(n * 10)
        return None


def test_two_robots_asking_each_other_at_once_are_both_answered_at_once() -> None:
    async def main() -> list[Curious]:
        clock, memory = VirtualClock(), MemoryTransport()
        layers = [Curious([2]), Curious([1])]
        async with Swarm(
            robot(i + 1, layer, transport=memory, clock=clock) for i, layer in enumerate(layers)
        ):
            await clock.sleep(5.0)
        return layers

    one, two = cas_async.run(main(), virtual=True)
    assert (one.answers, two.answers) == ([(10, 0.0)], [(20, 0.0)])
    assert one.timeouts == two.timeouts == 0


def test_a_swarm_of_robots_asking_each_other_has_no_timeouts() -> None:
    async def main() -> list[Curious]:
        clock, memory = VirtualClock(), MemoryTransport()
        ids = list(range(1, 11))
        layers = [Curious([o for o in ids if o != i], rounds=3) for i in ids]
        robots = [
            robot(i, layer, transport=memory, clock=clock)
            for i, layer in zip(ids, layers, strict=True)
        ]
        async with Swarm(robots):
            await clock.sleep(10.0)
        return layers

    layers = cas_async.run(main(), virtual=True)
    assert sum(layer.timeouts for layer in layers) == 0
    assert all(len(layer.answers) == 27 for layer in layers)
    assert max(t for layer in layers for _, t in layer.answers) == 0.0  # nobody waited


class Deferring(Layer):
    """Answers only some requests on arrival; the others reach handle_msg."""

    def __init__(self) -> None:
        self.handled: list[int] = []

    def get_msg_reply(self, msg: Message) -> Message | None:
        if isinstance(msg, Ping) and msg.n % 2 == 0:
            return Pong(msg.n + 1)
        return None  # not now: it goes to handle_msg

    async def handle_msg(self, msg: Message) -> None:
        match msg:
            case Ping(n=n):
                self.handled.append(n)
                self.reply(msg, Pong(-n))


class Asker(Layer):
    def __init__(self) -> None:
        self.got: list[int] = []


def test_get_msg_reply_may_leave_a_request_to_handle_msg() -> None:
    async def main() -> tuple[list[int], list[int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, answerer = Asker(), Deferring()
        async with Swarm(
            [
                robot(1, asker, transport=memory, clock=clock),
                robot(2, answerer, transport=memory, clock=clock),
            ]
        ):
            got = [(await asker.request(2, Ping(n), reply=Pong)).n for n in (2, 3, 4)]
        return got, answerer.handled

    assert cas_async.run(main(), virtual=True) == ([3, -3, 5], [3])


def test_a_repeated_request_is_answered_from_memory_not_by_get_msg_reply_again() -> None:
    calls: list[int] = []

    class Counting(Layer):
        def get_msg_reply(self, msg: Message) -> Message | None:
            calls.append(msg.msg_id)
            return Pong(1)

    async def main() -> dict[str, int]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker = Asker()
        robots = [
            robot(1, asker, transport=memory, clock=clock),
            robot(2, Counting(), transport=memory, clock=clock),
        ]
        async with Swarm(robots):
            ping = Ping(1, msg_type=MsgType.NEGOTIATION)
            asker.send(2, ping)
            await clock.sleep(1.0)
            asker.resend(2, ping)
            await clock.sleep(1.0)
            return robots[1].counters()

    counters = cas_async.run(main(), virtual=True)
    assert len(calls) == 1
    assert (counters["replies_resent"], counters["dropped.duplicate"]) == (1, 1)


def test_a_get_msg_reply_that_raises_fails_its_layer_like_any_hook() -> None:
    class Broken(Layer):
        def get_msg_reply(self, msg: Message) -> Message | None:
            raise ValueError("no answer today")

    async def main() -> None:
        clock, memory = VirtualClock(), MemoryTransport()
        asker = Asker()
        robots = [
            robot(1, asker, transport=memory, clock=clock),
            robot(2, Broken(), transport=memory, clock=clock),
        ]
        async with Swarm(robots) as swarm:
            asker.send(2, Ping(1, msg_type=MsgType.NEGOTIATION))
            await swarm.run()

    with pytest.raises(
        LayerError, match=r"robot 2, layer 0 \(Broken\) failed: ValueError: no answer today"
    ):
        cas_async.run(main(), virtual=True)


# -- 2. a periodic sender ------------------------------------------------------------------


class Beacon(Layer):
    """Sends a Ping every 0.1 s from its timer; the peer answers each one."""

    def __init__(self) -> None:
        self.sent: list[float] = []
        self.pongs = 0
        self.inner_runs = 0

    async def inner_process(self) -> None:
        self.inner_runs += 1
        if self.wake_due("beacon") is None and not self.sent:
            self.wake_after(0.1, "beacon")

    async def on_timer(self, key: Hashable) -> None:
        assert key == "beacon"
        self.sent.append(self.clock.now())
        self.send(2, Ping(len(self.sent), msg_type=MsgType.NEGOTIATION))
        self.wake_after(0.1, "beacon")

    async def handle_msg(self, msg: Message) -> None:
        self.pongs += 1


class Echo(Layer):
    def get_msg_reply(self, msg: Message) -> Message | None:
        return Pong(0)


def test_a_periodic_sender_sends_ten_messages_a_second_although_answers_come_in() -> None:
    async def main() -> Beacon:
        clock, memory = VirtualClock(), MemoryTransport()
        beacon = Beacon()
        robots = [
            robot(1, beacon, transport=memory, clock=clock),
            robot(2, Echo(), transport=memory, clock=clock),
        ]
        async with Swarm(robots):
            await clock.sleep(10.0 + 0.05)
        return beacon

    beacon = cas_async.run(main(), virtual=True)
    assert len(beacon.sent) == 100
    assert beacon.sent == pytest.approx([0.1 * k for k in range(1, 101)])
    assert beacon.pongs == 100
    assert beacon.inner_runs >= 100  # it ran after every answer, and sent nothing more


class Rearming(Layer):
    """Arms one key again and again: only the last deadline stands."""

    def __init__(self) -> None:
        self.fired: list[tuple[Hashable, float]] = []

    async def inner_process(self) -> None:
        if not self.fired and self.wake_due("x") is None:
            for delay in (5.0, 1.0, 3.0):
                self.wake_after(delay, "x")  # replaces: 3.0 stands
            self.wake_at(2.0, "y")
            self.wake_at(4.0, "z")
            assert self.cancel_wake("z")
            assert not self.cancel_wake("z")
            self.wake_at(0.5)  # the default key, None

    async def on_timer(self, key: Hashable) -> None:
        self.fired.append((key, self.clock.now()))


def test_timers_are_named_replaced_cancelled_and_told_by_key() -> None:
    async def main() -> Rearming:
        clock = VirtualClock()
        layer = Rearming()
        async with Robot(1, [layer], clock=clock, messages=MESSAGES):
            await clock.sleep(10.0)
            assert layer.wake_due("x") is None
        return layer

    assert cas_async.run(main(), virtual=True).fired == [(None, 0.5), ("y", 2.0), ("x", 3.0)]


class Punctual(Layer):
    """Arms timers at awkward instants and checks the clock when each goes off."""

    def __init__(self, instants: list[float]) -> None:
        self.instants = instants
        self.early: list[tuple[float, float]] = []
        self.told: list[Hashable] = []

    async def inner_process(self) -> None:
        if not self.told and self.wake_due(0) is None:
            for key, at in enumerate(self.instants):
                self.wake_at(at, key)

    async def on_timer(self, key: Hashable) -> None:
        assert isinstance(key, int)
        self.told.append(key)
        now = self.clock.now()
        if now < self.instants[key]:
            self.early.append((self.instants[key], now))


INSTANTS = [0.1 + k * 0.0137 for k in range(40)] + [1 / 3, 2 / 3, 0.3, 0.7]


@pytest.mark.parametrize("virtual", [True, False], ids=["virtual", "scaled"])
@pytest.mark.parametrize("use_uvloop", [False, True], ids=["stdlib", "uvloop"])
def test_a_timer_never_goes_off_before_its_instant(virtual: bool, use_uvloop: bool) -> None:
    if use_uvloop and virtual:
        pytest.skip("virtual time runs on its own loop, never on uvloop")
    if use_uvloop and not cas_async.uvloop_available():
        pytest.skip("uvloop is not installed")

    async def main() -> Punctual:
        clock = VirtualClock() if virtual else ScaledClock(100.0)
        layer = Punctual(INSTANTS)
        async with Robot(1, [layer], clock=clock, messages=MESSAGES):
            await clock.sleep(1.0)
        return layer

    layer = cas_async.run(main(), virtual=virtual, use_uvloop=use_uvloop)
    assert layer.early == []
    assert sorted(layer.told) == list(range(len(INSTANTS)))


def test_a_timer_at_an_instant_already_past_goes_off_at_once_and_nan_is_refused() -> None:
    class Late(Layer):
        def __init__(self) -> None:
            self.fired: list[float] = []

        async def inner_process(self) -> None:
            if not self.fired and self.wake_due() is None:
                with pytest.raises(ValueError, match="must be a number"):
                    self.wake_at(math.nan)
                self.wake_at(-5.0)

        async def on_timer(self, key: Hashable) -> None:
            self.fired.append(self.clock.now())

    async def main() -> list[float]:
        clock = VirtualClock()
        layer = Late()
        async with Robot(1, [layer], clock=clock, messages=MESSAGES):
            await clock.sleep(3.0)
        return layer.fired

    assert cas_async.run(main(), virtual=True) == [0.0]


# -- 3. robots that leave and join ---------------------------------------------------------


class Watcher(Layer):
    """Sends to robot 2 on demand; notes who joins and leaves."""

    def __init__(self) -> None:
        self.news: list[tuple[str, int, float]] = []

    async def on_robot_joined(self, robot_id: int) -> None:
        self.news.append(("joined", robot_id, self.clock.now()))

    async def on_robot_left(self, robot_id: int) -> None:
        self.news.append(("left", robot_id, self.clock.now()))


class Slow(Layer):
    """Answers in handle_msg after a long think."""

    async def handle_msg(self, msg: Message) -> None:
        await self.clock.sleep(100.0)
        self.reply(msg, Pong(0))


@pytest.mark.parametrize("kind", ["memory", "udp"])
def test_a_robot_that_leaves_costs_the_others_nothing_but_counts(kind: str) -> None:
    async def main() -> tuple[Watcher, dict[str, int], list[object], bool, bool]:
        clock = VirtualClock() if kind == "memory" else ScaledClock(50.0)
        transport = MemoryTransport() if kind == "memory" else UdpTransport()
        watcher = Watcher()
        robots = [
            robot(1, watcher, transport=transport, clock=clock),
            robot(2, Slow(), transport=transport, clock=clock),
        ]
        outcomes: list[object] = []
        async with Swarm(robots) as swarm:
            waiting = asyncio.ensure_future(watcher.request(2, Ping(1), timeout=1000.0))
            await clock.sleep(1.0)
            knew = watcher.knows(2)
            await swarm.remove(2)
            for attempt in (waiting, watcher.request(2, Ping(2), retries=3)):
                try:
                    await attempt
                except RobotGone as exc:
                    outcomes.append((type(exc).__name__, exc.peer, exc.attempts))
            watcher.send(2, Ping(3))  # gone: dropped and counted, never raised
            watcher.broadcast(Ping(4), robots=[2])
            await swarm.add(robot(3, Layer(), transport=transport, clock=clock))
            await clock.sleep(1.0)
            knows = watcher.knows(2), watcher.knows(3)
            counters = robots[0].counters()
        return watcher, counters, outcomes, knew, knows == (False, True)

    watcher, counters, outcomes, knew, knows = cas_async.run(main(), virtual=kind == "memory")
    assert knew
    assert knows
    assert outcomes == [("RobotGone", 2, 1), ("RobotGone", 2, 1)]
    assert counters["dropped.unknown_robot"] == 3  # the request, the send, the broadcast
    assert [(what, who) for what, who, _ in watcher.news] == [("left", 2), ("joined", 3)]
    if kind == "memory":
        assert [t for _, _, t in watcher.news] == [1.0, 1.0]  # told at once


def test_a_swarm_runs_until_the_robots_added_meanwhile_are_done() -> None:
    class Finite(Layer):
        def __init__(self, until: float) -> None:
            self.until = until
            self.done = False

        async def inner_process(self) -> None:
            if self.clock.now() >= self.until:
                self.done = True
            else:
                self.wake_at(self.until)

        def termination_condition(self) -> bool:
            return self.done

    async def main() -> float:
        clock, memory = VirtualClock(), MemoryTransport()
        async with Swarm([robot(1, Finite(1.0), transport=memory, clock=clock)]) as swarm:
            await swarm.add(robot(2, Finite(7.0), transport=memory, clock=clock))
            await swarm.run()
            return clock.now()

    assert cas_async.run(main(), virtual=True) == 7.0


def test_a_swarm_refuses_a_second_robot_with_an_id_and_removing_a_stranger() -> None:
    async def main() -> None:
        clock, memory = VirtualClock(), MemoryTransport()
        async with Swarm([robot(1, Layer(), transport=memory, clock=clock)]) as swarm:
            with pytest.raises(ConfigurationError, match="two robots with id 1"):
                await swarm.add(robot(1, Layer(), transport=memory, clock=clock))
            with pytest.raises(cas_async.UnknownRobotError, match="no robot 9 to remove"):
                await swarm.remove(9)

    cas_async.run(main(), virtual=True)


# -- 4. typed replies ----------------------------------------------------------------------


class Lower(Layer):
    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        match msg:
            case Ping(n=n) if n > 0:
                return Pong(n + 1)
            case Ping():
                return Ping(0)  # the wrong class
        return None


class Upper(Layer):
    """Asks below and other robots; answers a robot's Ping with a Pong."""

    def get_msg_reply(self, msg: Message) -> Message | None:
        return Pong(msg.n) if isinstance(msg, Ping) else None


def test_internal_and_external_replies_are_typed_or_refused_naming_both_classes() -> None:
    async def main() -> tuple[int, int, str, str]:
        clock, memory = VirtualClock(), MemoryTransport()
        upper = Upper()
        robots = [
            robot(1, upper, Lower(), transport=memory, clock=clock),
            robot(2, Upper(), Lower(), transport=memory, clock=clock),
        ]
        async with Swarm(robots):
            inside: Pong = await upper.request_down(Ping(4), reply=Pong)  # typed for mypy
            outside: Pong = await upper.request(2, Ping(7), reply=Pong)
            with pytest.raises(UnexpectedReply) as internal:
                await upper.request_down(Ping(-1), reply=Pong)
            with pytest.raises(UnexpectedReply) as external:
                await upper.request(2, Ping(1), reply=Ping)
        assert isinstance(external.value.reply, Pong)
        assert external.value.expected is Ping
        return inside.n, outside.n, str(internal.value), str(external.value)

    inside, outside, internal, external = cas_async.run(main(), virtual=True)
    assert (inside, outside) == (5, 7)
    assert "asked Ping #" in internal
    assert "for a Pong reply, got a Ping" in internal
    assert "for a Ping reply, got a Pong" in external


# -- 5. clear errors -----------------------------------------------------------------------


def test_robots_of_one_swarm_must_keep_one_time() -> None:
    with pytest.raises(
        ConfigurationError,
        match=r"robot 1 runs on ScaledClock\(time_factor=10\) and robot 2 on "
        r"ScaledClock\(time_factor=100\)",
    ):
        Swarm(
            [
                Robot(1, [Layer()], clock=ScaledClock(10)),
                Robot(2, [Layer()], clock=ScaledClock(100)),
            ]
        )
    with pytest.raises(ConfigurationError, match="same clock object"):
        Swarm([Robot(1, [Layer()], clock=VirtualClock()), Robot(2, [Layer()])])
    Swarm([Robot(1, [Layer()]), Robot(2, [Layer()])])  # two default clocks keep one time


def test_asking_above_the_top_is_counted_like_sending_above_the_top(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def main() -> dict[str, int]:
        top = Layer()
        async with Robot(1, [top, Layer()], clock=VirtualClock(), messages=MESSAGES) as bot:
            top.send_up(Ping(1))
            with pytest.raises(RuleViolation, match="no layer above to ask"):
                await top.request_up(Ping(2))
            return bot.dropped

    with caplog.at_level(logging.WARNING, logger="cas_async"):
        assert cas_async.run(main(), virtual=True) == {"no_layer_above": 2}
    lines = [r.getMessage() for r in caplog.records]
    assert any("Layer(L0) sent Ping(n=1) [not sent, ACCEPT]" in line for line in lines), lines
    assert not any("[#0" in line for line in lines)


def test_the_default_request_timeout_documents_itself() -> None:
    doc = inspect.getdoc(Layer.default_request_timeout) or ""
    assert doc.startswith("Simulated seconds a request waits for its reply")
    assert Layer.default_request_timeout == 5.0
