"""Internal throughput: messages/s from the top to the bottom of a 5-layer robot.

Framework: the top layer sends ``send_to_layer(4, msg)``, so every message is
forwarded by the 3 intermediate layers; the bottom layer counts in
``store_intra_msg``. Baseline: 5 asyncio tasks chained by unbounded
``asyncio.Queue``; the 3 middle tasks pass each message on, the last counts.

Both producers create a new ``Sample`` per message and yield the same way: a burst
of ``BURST`` messages, then ``await asyncio.sleep(0)``. The clock runs from the
first send to the arrival of the last message at the bottom.

Target: framework / baseline >= 0.8.
"""

from __future__ import annotations

import asyncio
import itertools
import sys
import time

from cas_async import Layer, Message, Robot

from ._common import MESSAGES, Bench, main, sample

LEVELS = 5
BURST = 64


class Top(Layer):
    def __init__(self, total: int) -> None:
        self.total = total
        self.started = 0.0

    async def inner_process(self) -> None:
        if self.started:
            return
        self.started = time.perf_counter()
        total = self.total
        for first in range(0, total, BURST):
            for n in range(first, min(first + BURST, total)):
                self.send_to_layer(LEVELS - 1, sample(n))
            await asyncio.sleep(0)


class Middle(Layer):
    """Forwards: the runtime passes messages through without calling a hook."""


class Bottom(Layer):
    def __init__(self, total: int, done: asyncio.Future[float]) -> None:
        self.total = total
        self.done = done
        self.count = 0

    async def store_intra_msg(self, msg: Message) -> None:
        self.count += 1
        if self.count == self.total:
            self.done.set_result(time.perf_counter())


async def framework(total: int) -> float:
    done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
    top = Top(total)
    layers = [top, Middle(), Middle(), Middle(), Bottom(total, done)]
    async with Robot(1, layers, messages=MESSAGES):
        end = await done
    # Every message really went through the three middle layers.
    assert all(layer.counters.forwarded == total for layer in layers[1:-1])
    return total / (end - top.started)


async def baseline(total: int) -> float:
    queues: list[asyncio.Queue[Message]] = [asyncio.Queue() for _ in range(LEVELS - 1)]
    done: asyncio.Future[float] = asyncio.get_running_loop().create_future()

    async def producer() -> float:
        started = time.perf_counter()
        first_queue = queues[0]
        for first in range(0, total, BURST):
            for n in range(first, min(first + BURST, total)):
                first_queue.put_nowait(sample(n))
            await asyncio.sleep(0)
        return started

    async def forward(inbox: asyncio.Queue[Message], outbox: asyncio.Queue[Message]) -> None:
        while True:
            outbox.put_nowait(await inbox.get())

    async def consumer(inbox: asyncio.Queue[Message]) -> None:
        count = 0
        while True:
            await inbox.get()
            count += 1
            if count == total:
                done.set_result(time.perf_counter())
                return

    tasks = [asyncio.create_task(forward(a, b)) for a, b in itertools.pairwise(queues)]
    tasks.append(asyncio.create_task(consumer(queues[-1])))
    try:
        started = await producer()
        end = await done
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    return total / (end - started)


BENCHES = [
    Bench(
        name="internal",
        unit="msg/s",
        framework=framework,
        baseline=baseline,
        size=200_000,
        quick_size=20_000,
        target=0.8,
    )
]

if __name__ == "__main__":
    sys.exit(main(BENCHES))
