"""An internal request its layer does not answer: counted while it waits, logged once when late.

The tutorial's idiom, ``await self.request_down(GoTo(...), timeout=math.inf)``, waits
for ever when the layer below returns ``None`` from ``get_intra_msg_reply`` and
never calls ``reply()``. The robot then lists the request
(``Robot.unanswered_requests``), its layer logs one warning once it has waited
``OVERDUE`` times its default timeout, and a scenario run reports the count.
"""

from __future__ import annotations

import asyncio
import logging
import math

import pytest

import cas_async
from cas_async import (
    Layer,
    MemoryTransport,
    Message,
    RequestTimeout,
    Robot,
    VirtualClock,
    message,
)
from cas_async._core._requests import OVERDUE
from cas_async.testing import Robots


@message(name="tests.GoTo")
class GoTo(Message):
    x: float


@message(name="tests.Arrived")
class Arrived(Message):
    x: float


MESSAGES = (GoTo, Arrived)


class Asker(Layer):
    """Asks the layer below to go to 1, 2, ... ``count`` at once, each without a time limit."""

    def __init__(self, count: int = 1, timeout: float = math.inf) -> None:
        self.count = count
        self.timeout = timeout
        self.arrived: list[float] = []
        self.failures: list[Exception] = []
        self.asked = False

    async def inner_process(self) -> None:
        if self.asked:
            return
        self.asked = True
        async with asyncio.TaskGroup() as requests:  # the layer waits here, as a Task layer does
            for x in range(self.count):
                requests.create_task(self.go(x + 1.0))

    async def go(self, x: float) -> None:
        try:
            answer = await self.request_down(GoTo(x), reply=Arrived, timeout=self.timeout)
        except RequestTimeout as exc:
            self.failures.append(exc)
        else:
            self.arrived.append(answer.x)


class Silent(Layer):
    """The mistake: no answer for GoTo, and no reply() later."""

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        return None


class Later(Layer):
    """Answers GoTo with reply(), ``delay`` simulated seconds after it came."""

    def __init__(self, delay: float) -> None:
        self.delay = delay
        self.waiting: dict[int, GoTo] = {}

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        match msg:
            case GoTo():
                self.waiting[msg.msg_id] = msg
                self.wake_after(self.delay, msg.msg_id)
        return None

    async def on_timer(self, key: object) -> None:
        match key:
            case int(msg_id):
                request = self.waiting.pop(msg_id)
                self.reply(request, Arrived(request.x))


def late_warnings(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if "has waited" in r.getMessage()]


@pytest.mark.cas_virtual
async def test_a_request_nobody_answers_is_listed_and_logged_once(
    cas_robots: Robots, cas_memory: MemoryTransport, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="cas_async")
    asker = Asker(count=3)
    robot = await cas_robots.start(1, [asker, Silent()], transport=cas_memory, messages=MESSAGES)
    await asyncio.sleep(1.0)
    assert robot.unanswered_requests() == {"Asker(L0) asked Silent(L1) for GoTo": 3}
    assert late_warnings(caplog) == []
    late = OVERDUE * Layer.default_request_timeout  # 50 s: far longer than the default 5 s
    await asyncio.sleep(late)
    warnings = sorted(late_warnings(caplog))
    assert len(warnings) == 3  # one per request
    assert [w.split(" has")[0] for w in warnings] == [
        f"robot 1 Asker(L0): GoTo #{n}" for n in (1, 2, 3)
    ]
    assert warnings[0] == (
        "robot 1 Asker(L0): GoTo #1 has waited 50 s for the reply from Silent(L1): "
        "Silent.get_intra_msg_reply returned None and no reply() followed "
        "(it waits up to its timeout, inf s)"
    )
    await asyncio.sleep(10 * late)
    assert len(late_warnings(caplog)) == 3  # once per request, not a flood
    assert robot.unanswered_requests() == {"Asker(L0) asked Silent(L1) for GoTo": 3}
    assert asker.arrived == []


@pytest.mark.cas_virtual
async def test_a_reply_that_comes_later_clears_the_note(
    cas_robots: Robots, cas_memory: MemoryTransport, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="cas_async")
    asker = Asker(count=2)
    robot = await cas_robots.start(
        1, [asker, Later(delay=20.0)], transport=cas_memory, messages=MESSAGES
    )
    await asyncio.sleep(1.0)
    assert robot.unanswered_requests() == {"Asker(L0) asked Later(L1) for GoTo": 2}
    await asyncio.sleep(100.0)
    assert sorted(asker.arrived) == [1.0, 2.0]
    assert robot.unanswered_requests() == {}
    assert late_warnings(caplog) == []  # answered within 50 s: nothing to say


@pytest.mark.cas_virtual
async def test_a_request_that_timed_out_is_no_longer_waiting(
    cas_robots: Robots, cas_memory: MemoryTransport
) -> None:
    asker = Asker(timeout=3.0)
    robot = await cas_robots.start(1, [asker, Silent()], transport=cas_memory, messages=MESSAGES)
    await asyncio.sleep(1.0)
    assert robot.unanswered_requests() == {"Asker(L0) asked Silent(L1) for GoTo": 1}
    await asyncio.sleep(5.0)
    assert [str(exc) for exc in asker.failures] == [
        "robot 1 Asker(L0): no reply from layer 1 to GoTo #1 within 3 s"
    ]
    assert robot.unanswered_requests() == {}


class Patient(Asker):
    default_request_timeout = math.inf


@pytest.mark.cas_virtual
async def test_a_layer_without_a_default_timeout_is_never_warned_about(
    cas_robots: Robots, cas_memory: MemoryTransport, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="cas_async")
    robot = await cas_robots.start(
        1, [Patient(), Silent()], transport=cas_memory, messages=MESSAGES
    )
    await asyncio.sleep(10_000.0)
    assert robot.unanswered_requests() == {"Patient(L0) asked Silent(L1) for GoTo": 1}
    assert late_warnings(caplog) == []


def test_stopping_the_robot_disarms_the_warning(caplog: pytest.LogCaptureFixture) -> None:
    async def main() -> None:
        robot = Robot(
            1, [Asker(), Silent()], transport=MemoryTransport(), clock=VirtualClock(),
            messages=MESSAGES,
        )  # fmt: skip
        async with robot:
            await asyncio.sleep(1.0)
            assert robot.unanswered_requests() == {"Asker(L0) asked Silent(L1) for GoTo": 1}
        await asyncio.sleep(1000.0)  # the warning's instant passes with the robot stopped
        assert robot.unanswered_requests() == {}

    caplog.set_level(logging.WARNING, logger="cas_async")
    cas_async.run(main(), virtual=True)
    assert late_warnings(caplog) == []
