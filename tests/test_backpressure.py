"""Bounded inboxes: internal senders slow to their consumer's pace, floods are dropped."""

from __future__ import annotations

import asyncio

import pytest

import cas_async
from cas_async import Layer, LayerError, MemoryTransport, Message, Robot, Swarm, VirtualClock
from tests.stacks import STACK_MESSAGES, Answer, Note, Query

BURST = 5
TOTAL = 100


class Producer(Layer):
    """Sends ``TOTAL`` notes to layer ``to``, ``BURST`` per wake, one wake every ``period``.

    A neighbour gets them with ``send_down``/``send_up``, a farther layer with
    ``send_to_layer`` (through the layers between).
    """

    def __init__(self, to: int, period: float) -> None:
        self.to = to
        self.period = period
        self.sent = 0
        self.bursts: list[float] = []  # when each burst went out
        self.before_burst: list[int] = []  # the consumer's inbox then
        self.peak = 0  # the consumer's inbox at its fullest

    async def inner_process(self) -> None:
        if self.sent >= TOTAL:
            return
        sizes = self.robot.inbox_sizes
        self.bursts.append(self.clock.now())
        self.before_burst.append(sizes()[self.to])
        for _ in range(BURST):
            note = Note(str(self.sent), [])
            if self.to == self.level + 1:
                self.send_down(note)
            elif self.to == self.level - 1:
                self.send_up(note)
            else:
                self.send_to_layer(self.to, note)
            self.sent += 1
            self.peak = max(self.peak, sizes()[self.to])
        self.wake_after(self.period)


class Consumer(Layer):
    """Takes ``pace`` simulated seconds per message."""

    def __init__(self, pace: float) -> None:
        self.pace = pace
        self.got: list[str] = []
        self.times: list[float] = []

    async def store_intra_msg(self, msg: Message) -> None:
        await self.clock.sleep(self.pace)
        assert isinstance(msg, Note)
        self.got.append(msg.text)
        self.times.append(self.clock.now())

    def termination_condition(self) -> bool:
        return len(self.got) >= TOTAL


class Middle(Layer):
    """Only forwards."""


Run = tuple[Producer, Consumer, dict[str, int], float]


def produce(layout: str, limit: int, period: float, pace: float) -> Run:
    """Runs a producer and a consumer laid out as ``layout`` until everything is consumed."""

    async def main() -> Run:
        clock = VirtualClock()
        consumer = Consumer(pace)
        if layout == "down":
            producer = Producer(1, period)
            stack: list[Layer] = [producer, consumer]
        elif layout == "up":
            producer = Producer(0, period)
            stack = [consumer, producer]
        else:  # through a forwarding layer
            producer = Producer(2, period)
            stack = [producer, Middle(), consumer]
        robot = Robot(1, stack, clock=clock, messages=STACK_MESSAGES, queue_limit=limit)
        async with robot:
            async with asyncio.timeout(10_000):  # virtual: a hang fails here, it does not hang
                await robot.run()
        return producer, consumer, robot.dropped, clock.now()

    return cas_async.run(main(), virtual=True)


LAYOUTS = ["down", "up", "through-a-middle-layer"]


@pytest.mark.parametrize("layout", LAYOUTS)
def test_a_fast_producer_slows_to_its_consumer_s_pace(layout: str) -> None:
    producer, consumer, dropped, _ = produce(layout, limit=10, period=1.0, pace=0.5)
    assert consumer.got == [str(k) for k in range(TOTAL)]  # all of them, in order
    assert dropped == {}
    assert producer.peak <= 10 + BURST
    # It did wait: bursts came later than every second, and each burst after a wait
    # went out as soon as the consumer's inbox had drained to half the limit.
    gaps = [b - a for a, b in zip(producer.bursts, producer.bursts[1:], strict=False)]
    assert max(gaps) > 1.0
    assert min(gaps) >= 1.0
    waited = [n for gap, n in zip(gaps, producer.before_burst[1:], strict=True) if gap > 1.0]
    assert waited
    assert set(waited) == {10 // 2}
    # The consumer never ran dry: it took one message every 0.5 s from the start.
    assert consumer.times == [0.5 * (k + 1) for k in range(TOTAL)]


@pytest.mark.parametrize("layout", LAYOUTS)
def test_with_room_to_spare_the_producer_never_waits(layout: str) -> None:
    producer, consumer, dropped, end = produce(layout, limit=1_000, period=1.0, pace=0.5)
    assert producer.bursts == [float(k) for k in range(TOTAL // BURST)]
    assert producer.peak > 10 + BURST  # the backlog a limit of 10 would have held back
    assert consumer.got == [str(k) for k in range(TOTAL)]
    assert consumer.times == [0.5 * (k + 1) for k in range(TOTAL)]
    assert (dropped, end) == ({}, 50.0)


@pytest.mark.parametrize("limit", [10, 10_000])
def test_a_consumer_that_keeps_up_never_holds_its_producer_back(limit: int) -> None:
    producer, consumer, dropped, _ = produce("down", limit=limit, period=1.0, pace=0.1)
    assert producer.bursts == [float(k) for k in range(TOTAL // BURST)]
    assert producer.peak <= BURST
    # Each burst is consumed in the half second after it went out.
    assert consumer.times == [
        pytest.approx(burst + 0.1 * (k + 1)) for burst in producer.bursts for k in range(BURST)
    ]
    assert dropped == {}


# -- layers that flood each other ---------------------------------------------------------


TTL = 9
SEEDS = 15  # each layer starts by sending this many: above the limit of 10


class Echo(Layer):
    """Seeds ``SEEDS`` notes to ``peer``, then answers each note with one, until its TTL."""

    def __init__(self, peer: int, pace: float) -> None:
        self.peer = peer
        self.pace = pace
        self.handled = 0
        self.expected = 0
        self.peak = 0

    async def inner_process(self) -> None:
        if self.handled == 0:
            for _ in range(SEEDS):
                self.send_to_layer(self.peer, Note("seed", []))

    async def store_intra_msg(self, msg: Message) -> None:
        assert isinstance(msg, Note)
        self.handled += 1
        self.peak = max(self.peak, self.robot.inbox_sizes()[self.level] + 1)
        if self.pace:
            await self.clock.sleep(self.pace)
        if len(msg.hops) < TTL:
            self.send_to_layer(self.peer, Note("echo", [*msg.hops, self.level]))

    def termination_condition(self) -> bool:
        return self.handled >= self.expected


@pytest.mark.parametrize("pace", [0.0, 0.01], ids=["instant", "slow"])
@pytest.mark.parametrize(
    "peers",
    [
        pytest.param((1, 0), id="two-neighbours"),
        pytest.param((2, 0, 1), id="a-cycle-of-three-layers"),
    ],
)
def test_layers_flooding_each_other_do_not_deadlock(pace: float, peers: tuple[int, ...]) -> None:
    # Each seed starts a chain of TTL + 1 messages handled alternately around the cycle.
    handled_each = SEEDS * (TTL + 1)

    async def main() -> tuple[list[int], list[int], float]:
        clock = VirtualClock()
        stack = [Echo(peer, pace) for peer in peers]
        for layer in stack:
            layer.expected = handled_each
        robot = Robot(1, stack, clock=clock, messages=STACK_MESSAGES, queue_limit=10)
        async with robot:
            async with asyncio.timeout(1_000):  # virtual: a deadlock fails here
                await robot.run()
            await clock.sleep(1.0)  # nothing further arrives
        return [layer.handled for layer in stack], [layer.peak for layer in stack], clock.now()

    handled, peaks, end = cas_async.run(main(), virtual=True)
    assert handled == [handled_each] * len(peers)
    assert max(peaks) <= SEEDS * len(peers)  # no message appeared from nowhere
    # Some layer was always at work (never all of them waiting), plus the final second.
    work = pace * handled_each
    assert work + 1.0 <= end + 1e-9
    assert end <= work * len(peers) + 1.0 + 1e-9


class Asked(Layer):
    """A producer that floods its consumer past the queue limit, and answers requests."""

    async def inner_process(self) -> None:
        if self.counters.sent_internal == 0:
            for k in range(20):  # twice the limit: this layer then waits for room
                self.send_down(Note(str(k), []))

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        return Answer(1, 0)


def test_a_consumer_may_ask_its_producer_while_the_producer_waits_for_room() -> None:
    class Asking(Layer):
        def __init__(self) -> None:
            self.got: list[str] = []

        async def store_intra_msg(self, msg: Message) -> None:
            assert isinstance(msg, Note)
            if not self.got:
                await self.request_up(Query(1), timeout=5.0)  # e.g. "may I go on?"
            self.got.append(msg.text)

        def termination_condition(self) -> bool:
            return len(self.got) >= 20

    async def main() -> tuple[list[str], float]:
        clock = VirtualClock()
        asking = Asking()
        robot = Robot(1, [Asked(), asking], clock=clock, messages=STACK_MESSAGES, queue_limit=10)
        async with robot:
            await robot.run()
        return asking.got, clock.now()

    try:
        got, end = cas_async.run(main(), virtual=True)
    except LayerError as error:
        pytest.fail(f"the request deadlocked until its timeout: {error}")
    assert (got, end) == ([str(k) for k in range(20)], 0.0)


class Helper(Layer):
    def __init__(self) -> None:
        self.asked = 0

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        self.asked += 1
        return Answer(2, self.level)


@pytest.mark.parametrize(
    "producer_first",
    [
        pytest.param(True, id="producer-asked-first"),
        pytest.param(False, id="producer-asked-last"),
    ],
)
def test_a_consumer_may_ask_its_producer_and_another_layer_at_once(producer_first: bool) -> None:
    class Asking(Layer):
        def __init__(self) -> None:
            self.got: list[str] = []

        async def store_intra_msg(self, msg: Message) -> None:
            assert isinstance(msg, Note)
            if not self.got:
                asks = [self.request_up(Query(1), timeout=5.0), self.request_down(Query(2))]
                await asyncio.gather(*(asks if producer_first else reversed(asks)))
            self.got.append(msg.text)

        def termination_condition(self) -> bool:
            return len(self.got) >= 20

    async def main() -> tuple[list[str], float, int]:
        clock = VirtualClock()
        asking, helper = Asking(), Helper()
        robot = Robot(
            1, [Asked(), asking, helper], clock=clock, messages=STACK_MESSAGES, queue_limit=10
        )
        async with robot:
            await robot.run()
        return asking.got, clock.now(), helper.asked

    try:
        got, end, asked = cas_async.run(main(), virtual=True)
    except LayerError as error:
        pytest.fail(f"the request deadlocked until its timeout: {error}")
    assert (got, end, asked) == ([str(k) for k in range(20)], 0.0, 1)


# -- a flood from another robot ---------------------------------------------------------


class Slow(Layer):
    """Takes a tenth of a simulated second per external message."""

    def __init__(self) -> None:
        self.handled = 0
        self.peak = 0

    async def handle_msg(self, msg: Message) -> None:
        self.handled += 1
        self.peak = max(self.peak, self.robot.inbox_sizes()[self.level] + 1)
        await self.clock.sleep(0.1)


class Ticker(Layer):
    """Wakes every simulated second."""

    def __init__(self) -> None:
        self.ticks: list[float] = []

    async def inner_process(self) -> None:
        self.ticks.append(self.clock.now())
        self.wake_after(1.0)


def test_an_external_flood_is_dropped_at_the_limit_and_does_not_starve_other_layers() -> None:
    limit, floods, size = 50, 6, 3_000

    async def main() -> tuple[Slow, Ticker, dict[str, int], list[int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        slow, ticker = Slow(), Ticker()
        victim = Robot(
            1,
            [slow, ticker],
            transport=memory,
            clock=clock,
            messages=STACK_MESSAGES,
            queue_limit=limit,
        )
        flooder = [Layer(), Layer()]
        robots = [victim, Robot(2, flooder, transport=memory, clock=clock, messages=STACK_MESSAGES)]
        after_flood: list[int] = []
        async with Swarm(robots):
            for _ in range(floods):
                await clock.sleep(0.75)
                for k in range(size):  # thousands in one go, none of them yielding
                    flooder[0].send(1, Note(str(k), []))
                await asyncio.sleep(0)  # the datagrams are delivered (call_soon)
                after_flood.append(victim.inbox_sizes()[slow.level])
            await clock.sleep(20.0 - clock.now())
        return slow, ticker, victim.dropped, after_flood

    slow, ticker, dropped, after_flood = cas_async.run(main(), virtual=True)
    assert set(dropped) == {"queue_full"}
    assert slow.handled + dropped["queue_full"] == floods * size
    assert max(after_flood) == limit  # each flood filled the inbox up to the limit, no more
    assert slow.peak <= limit
    assert slow.handled <= limit * floods
    assert ticker.ticks == [float(t) for t in range(21)]  # on schedule all along


def test_a_reply_reaches_its_request_even_when_the_inbox_is_full() -> None:
    class Asking(Layer):
        """Asks robot 3 while handling its first message; the flood piles up meanwhile."""

        def __init__(self) -> None:
            self.replies: list[tuple[int, float]] = []

        async def handle_msg(self, msg: Message) -> None:
            if not self.replies:
                reply = await self.request(3, Query(4), timeout=10.0)
                assert isinstance(reply, Answer)
                self.replies.append((reply.value, self.clock.now()))

    class Answering(Layer):
        async def handle_msg(self, msg: Message) -> None:
            await self.clock.sleep(2.0)
            assert isinstance(msg, Query)
            self.reply(msg, Answer(msg.value * 2, 0))

    async def main() -> tuple[list[tuple[int, float]], int, dict[str, int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        asking, flooder = Asking(), Layer()

        def make(robot_id: int, layer: Layer, queue_limit: int = 10_000) -> Robot:
            return Robot(
                robot_id,
                [layer],
                transport=memory,
                clock=clock,
                messages=STACK_MESSAGES,
                queue_limit=queue_limit,
            )

        victim = make(1, asking, queue_limit=10)
        async with Swarm([victim, make(2, flooder), make(3, Answering())]):
            flooder.send(1, Note("first", []))
            await clock.sleep(1.0)  # handling "first": waiting for robot 3's answer
            for k in range(100):
                flooder.send(1, Note(str(k), []))
            await clock.sleep(1.0)
            full = victim.inbox_sizes()[0]
            await clock.sleep(5.0)
        return asking.replies, full, victim.dropped

    replies, full, dropped = cas_async.run(main(), virtual=True)
    assert full == 10
    assert replies == [(8, 2.0)]  # not refused as queue_full
    assert dropped == {"queue_full": 90}
