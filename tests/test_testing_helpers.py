"""The helpers of cas_async.testing, each shown catching what it is for."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from pathlib import Path

import pytest

import cas_async
from cas_async import (
    FaultyTransport,
    Layer,
    MemoryTransport,
    Message,
    MsgType,
    Robot,
    UdpTransport,
    VirtualClock,
    message,
)
from cas_async.testing import (
    Recorder,
    Robots,
    RunUntilTimeout,
    UnexpectedDrops,
    assert_roundtrip,
    run_scenario_file,
    run_until,
    wait_all_tasks_blocked,
)


@message
class Hop(Message):
    left: int


@message
class Level(Message):
    x: float
    names: list[str]


async def test_wait_all_tasks_blocked_waits_for_a_chain_of_any_length() -> None:
    # A hand-off of 500 steps (20 rounds of sleep(0), the old settle(), saw 20 of them).
    done: list[int] = []

    def step(n: int) -> None:
        if n:
            asyncio.get_running_loop().call_soon(step, n - 1)
        else:
            done.append(n)

    step(500)
    await wait_all_tasks_blocked()
    assert done == [0]


async def test_wait_all_tasks_blocked_does_not_move_time_past_a_timer() -> None:
    fired: list[str] = []
    asyncio.get_running_loop().call_later(3600, fired.append, "late")
    await wait_all_tasks_blocked()
    assert fired == []  # waiting on a timer is being blocked


async def test_two_tasks_may_wait_for_the_loop_at_once() -> None:
    # Each would see the other's polling as work, were there two pollers.
    done: list[int] = []
    asyncio.get_running_loop().call_soon(done.append, 1)
    await asyncio.gather(wait_all_tasks_blocked(), wait_all_tasks_blocked())
    assert done == [1]


async def spin() -> None:
    while True:
        await asyncio.sleep(0)


async def a_spinner_is_named() -> None:
    spinner = asyncio.ensure_future(spin())
    try:
        with pytest.raises(RuntimeError, match="a task never waits"):
            await wait_all_tasks_blocked()
    finally:
        spinner.cancel()


async def test_wait_all_tasks_blocked_names_a_task_that_never_waits() -> None:
    await a_spinner_is_named()


def test_on_virtual_time_too_a_task_that_never_waits_is_named() -> None:
    cas_async.run(a_spinner_is_named(), virtual=True)


def test_on_virtual_time_it_returns_before_time_moves_on() -> None:
    async def main() -> tuple[float, list[int]]:
        loop = asyncio.get_running_loop()
        done: list[int] = []
        loop.call_soon(lambda: loop.call_soon(done.append, 1))
        loop.call_later(5.0, done.append, 2)
        await wait_all_tasks_blocked()
        return loop.time(), list(done)

    assert cas_async.run(main(), virtual=True) == (0.0, [1])


def test_run_until_returns_when_true_and_names_what_stayed_false() -> None:
    async def main() -> tuple[float, str]:
        loop = asyncio.get_running_loop()
        flag: list[bool] = []
        loop.call_later(42.0, flag.append, True)
        await run_until(lambda: flag, timeout=100.0)
        reached = loop.time()
        with pytest.raises(RunUntilTimeout) as caught:
            await run_until(lambda: False, timeout=5.0, what="the impossible")
        return reached, str(caught.value)

    reached, message_ = cas_async.run(main(), virtual=True)
    assert 42.0 <= reached < 42.1
    assert message_ == "the impossible still false after 5 s"


def test_recorder_records_and_answers_requests() -> None:
    class Asker(Layer):
        pass

    async def main() -> tuple[list[Message], Message, list[Message]]:
        memory, clock = MemoryTransport(), VirtualClock()
        answering = Recorder(answer=lambda m: Hop(m.left - 1) if isinstance(m, Hop) else None)
        asker = Asker()
        robots = Robots()
        await robots.start(1, [answering], transport=memory, clock=clock, messages=[Hop])
        await robots.start(2, [asker], transport=memory, clock=clock, messages=[Hop])
        asker.send(1, Hop(9))
        reply = await asker.request(1, Hop(5), reply=Hop, timeout=1.0)
        await robots.aclose()
        return answering.external, reply, answering.requests

    external, reply, requests = cas_async.run(main(), virtual=True)
    assert [m.left for m in external if isinstance(m, Hop)] == [9]
    assert isinstance(reply, Hop)
    assert reply.left == 4
    assert [m.msg_type for m in requests] == [MsgType.NEGOTIATION]


def test_robots_raise_the_failure_of_a_layer_when_closed() -> None:
    class Breaks(Layer):
        async def handle_msg(self, msg: Message) -> None:
            raise ValueError("broken on purpose")

    async def main() -> None:
        memory, clock = MemoryTransport(), VirtualClock()
        robots = Robots()
        await robots.start(2, [Breaks()], transport=memory, clock=clock, messages=[Hop])
        sender = Recorder()
        await robots.start(1, [sender], transport=memory, clock=clock, messages=[Hop])
        sender.send(2, Hop(1))
        await asyncio.sleep(1.0)
        await robots.aclose()

    with pytest.raises(cas_async.LayerError, match="broken on purpose"):
        cas_async.run(main(), virtual=True)


def test_robots_report_drops_not_allowed_by_robot_and_reason() -> None:
    async def main(robots: Robots) -> None:
        sender = Recorder()
        await robots.start(1, [sender], transport=MemoryTransport(), messages=[Hop])
        sender.send(7, Hop(1))  # nobody is robot 7
        await robots.aclose()

    with pytest.raises(UnexpectedDrops, match=r"robot 1: \{'unknown_robot': 1\}"):
        cas_async.run(main(Robots()), virtual=True)
    cas_async.run(main(Robots(allowed_drops={"unknown_robot"})), virtual=True)


def test_assert_roundtrip_returns_the_copy_and_names_what_does_not_survive() -> None:
    original = Level(1.5, ["a", "b"])
    original.msg_id, original.robot_id = 7, 3
    copy = assert_roundtrip(original)
    assert copy == original
    assert copy is not original
    assert (copy.msg_id, copy.robot_id) == (7, 3)
    with pytest.raises(AssertionError, match="does not survive the codec"):
        assert_roundtrip(Level(1.0, [1]))  # type: ignore[list-item]  # an int in list[str]
    nan = assert_roundtrip(Level(math.nan, []))
    assert math.isnan(nan.x)


def test_robots_default_to_a_virtual_clock_on_the_virtual_loop() -> None:
    async def main() -> Robot:
        robots = Robots()
        robot = await robots.start(1, [Recorder()], transport=MemoryTransport(), messages=[Hop])
        await robots.aclose()
        return robot

    assert isinstance(cas_async.run(main(), virtual=True).clock, VirtualClock)


# -- the plugin's fixtures, used by this suite as by any other -----------------------------


@pytest.mark.cas_virtual
async def test_cas_lossy_loses_as_told_and_the_same_way_each_time(
    cas_robots: Robots, cas_lossy: Callable[..., FaultyTransport]
) -> None:
    async def heard(seed: int) -> list[int]:
        transport = cas_lossy(loss=0.5, seed=seed)
        listener, sender = Recorder(), Recorder()
        await cas_robots.start(10 * seed + 1, [listener], transport=transport, messages=[Hop])
        await cas_robots.start(10 * seed + 2, [sender], transport=transport, messages=[Hop])
        for n in range(40):
            sender.send(10 * seed + 1, Hop(n))
        await wait_all_tasks_blocked()
        return [m.left for m in listener.of_type(Hop)]

    first, again, other = await heard(1), await heard(1), await heard(2)
    assert 5 < len(first) < 35  # about half
    assert first == again  # seeded
    assert first != other


async def test_cas_udp_carries_messages_between_robots_on_loopback(
    cas_robots: Robots, cas_udp: UdpTransport
) -> None:
    listener, sender = Recorder(), Recorder()
    robot = await cas_robots.start(1, [listener], transport=cas_udp, messages=[Hop])
    await cas_robots.start(2, [sender], transport=cas_udp, messages=[Hop])
    assert robot.address[0] == "127.0.0.1"  # type: ignore[index]
    assert robot.address[1] > 0  # type: ignore[index]
    sender.send(1, Hop(3))
    await run_until(lambda: listener.external, timeout=5.0)
    assert [m.left for m in listener.of_type(Hop)] == [3]


SHIPPED = Path(__file__).resolve().parents[1] / "apps" / "fire_brigade" / "scenarios"


def test_run_scenario_file_runs_in_virtual_time_with_overrides() -> None:
    seen: list[int] = []
    outcome = run_scenario_file(
        SHIPPED / "thesis_5_8_1.toml",
        "mission.buckets=3",
        "run.seed=5",
        observe=lambda environment: seen.append(len(environment.robot_ids)),
    )
    assert outcome.result.status.value == "completed"
    assert (outcome.result.target, outcome.result.delivered) == (3, 3)
    assert outcome.result.seed == 5
    assert seen == [20]  # observed before the robots started
    assert outcome.environment.items.retired == 3
    again = run_scenario_file(SHIPPED / "thesis_5_8_1.toml", "mission.buckets=3", "run.seed=5")
    assert again.result.makespan == outcome.result.makespan  # virtual time: the same run


async def test_run_scenario_file_says_what_to_do_in_an_async_test() -> None:
    with pytest.raises(RuntimeError, match=r"await cas_async\.scenario\.run_scenario"):
        run_scenario_file(SHIPPED / "thesis_5_8_1.toml")
