"""A scenario run from inside an asyncio service: ScenarioRun.now()/progress(), BackgroundRun.

The service's own loop is pytest-asyncio's (real time); the run gets a loop of its
own in a worker thread, virtual or scaled, and the service awaits it, reads its
progress and stops it without making a thread of its own.
"""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path

import pytest

import cas_async
from cas_async import ConfigurationError, RobotStateError
from cas_async.scenario import (
    BackgroundRun,
    RunProgress,
    RunStatus,
    ScenarioRun,
    load_scenario,
)

ROOT = Path(__file__).resolve().parents[2]
GATHERING = ROOT / "examples" / "gathering" / "gathering.toml"
FIRE_BRIGADE = ROOT / "apps" / "fire_brigade" / "scenarios" / "thesis_5_8_1.toml"
LIMIT = 120.0
"""Wall seconds any run here may take (a few tenths, unless something hangs)."""


def test_scenario_run_says_where_it_stands_on_its_own_loop() -> None:
    scenario = load_scenario(GATHERING)
    seen: list[RunProgress] = []

    async def main() -> ScenarioRun:
        run = ScenarioRun(scenario)
        assert run.now() == 0.0  # built, not started
        assert run.progress() == RunProgress(0.0, 0, 5, 0, None)

        async def watch() -> None:
            while True:
                seen.append(run.progress())
                await asyncio.sleep(1.0)  # a simulated second: this loop is virtual

        async with run:
            watching = asyncio.ensure_future(watch())
            result = await run.until_done()
            watching.cancel()
            assert run.now() == result.sim_time
        return run

    run = cas_async.run(main(), virtual=True)
    result = run.result
    assert result.status is RunStatus.COMPLETED
    assert result.makespan is not None
    times = [p.time for p in seen]
    assert times == sorted(times)
    assert times[1:4] == [1.0, 2.0, 3.0]
    assert all(p.status is None and p.target == 5 for p in seen)
    assert [p.done for p in seen] == sorted(p.done for p in seen)
    final = run.progress()
    assert final == RunProgress(result.sim_time, 5, 5, final.detail, RunStatus.COMPLETED)
    assert final.ended
    assert final.fraction == 1.0


async def test_a_virtual_run_is_awaited_from_a_service_loop() -> None:
    service_loop = asyncio.get_running_loop()
    assert not isinstance(service_loop, cas_async.VirtualTimeLoop)
    run = BackgroundRun(load_scenario(GATHERING))
    assert run.progress() == RunProgress()  # nothing yet
    async with asyncio.timeout(LIMIT):
        result = await run
    assert result.status is RunStatus.COMPLETED
    assert run.done
    final = run.progress()
    assert final.status is RunStatus.COMPLETED
    assert final.time == result.sim_time
    assert (final.done, final.target) == (5, 5)
    assert run.trace.times[-1] == result.makespan
    # The same seed on the usual path gives the same run: the thread changes nothing.
    again = await asyncio.to_thread(cas_async.run, _run_directly(GATHERING), virtual=True)
    assert again.makespan == result.makespan
    assert again.messages_external == result.messages_external


async def _run_directly(path: Path) -> cas_async.scenario.RunResult:
    run = ScenarioRun(load_scenario(path))
    async with run:
        return await run.until_done()


async def test_progress_is_read_from_the_service_while_the_run_goes() -> None:
    scenario = load_scenario(
        GATHERING, ["run.virtual=false", "run.time_factor=20", "run.progress_interval=0.02"]
    )
    ticks = 0

    async def tick() -> None:  # the service's own work goes on meanwhile
        nonlocal ticks
        while True:
            ticks += 1
            await asyncio.sleep(0.01)

    ticking = asyncio.ensure_future(tick())
    seen: list[RunProgress] = []
    async with asyncio.timeout(LIMIT), BackgroundRun(scenario) as run:
        while not run.done:
            seen.append(run.progress())
            await asyncio.sleep(0.01)
        result = await run
    ticking.cancel()
    assert result.status is RunStatus.COMPLETED
    assert ticks > 10
    running = [p for p in seen if p.status is None and p.time > 0]
    assert running, seen[:5]  # it was seen under way, not only before and after
    assert [p.time for p in seen] == sorted(p.time for p in seen)
    assert all(p.time <= result.sim_time for p in seen)


async def test_stop_from_the_service_ends_the_run_interrupted() -> None:
    scenario = load_scenario(
        FIRE_BRIGADE,
        ["run.virtual=true", 'run.transport="memory"', "mission.buckets=100000",
         "run.max_time=1000000"],
    )  # fmt: skip
    run = BackgroundRun(scenario)
    run.start()
    async with asyncio.timeout(LIMIT):
        while run.progress().time < 5.0:  # under way
            await asyncio.sleep(0.01)
        run.stop()
        result = await run
    assert result.status is RunStatus.INTERRUPTED
    assert run.progress().status is RunStatus.INTERRUPTED
    assert 5.0 <= result.sim_time < 1000000


async def test_a_run_stopped_before_it_starts_runs_nothing() -> None:
    run = BackgroundRun(load_scenario(GATHERING))
    run.stop()
    async with asyncio.timeout(LIMIT):
        result = await run
    assert result.status is RunStatus.INTERRUPTED
    assert result.sim_time == 0.0


async def test_a_scenario_that_cannot_run_raises_where_it_is_awaited(tmp_path: Path) -> None:
    path = tmp_path / "refused.toml"
    path.write_text(
        'app = "tests.startup_apps:refuses_to_build"\n[run]\nvirtual = true\n'
        "[world]\nwidth = 10\nheight = 10\n"
    )
    run = BackgroundRun(load_scenario(path))
    with pytest.raises(ConfigurationError, match="at most 1 robot on Tuesdays"):
        async with asyncio.timeout(LIMIT):
            await run
    assert run.done


async def test_a_run_runs_once() -> None:
    endless = ["run.virtual=true", 'run.transport="memory"', "mission.buckets=100000"]
    run = BackgroundRun(load_scenario(FIRE_BRIGADE, endless))  # ends when stopped
    run.start()
    with pytest.raises(RobotStateError, match="started already"):
        run.start()
    with pytest.raises(RobotStateError, match="has not ended"):
        _ = run.trace
    run.stop()
    async with asyncio.timeout(LIMIT):
        await run
    threads = [t for t in threading.enumerate() if t.name.startswith("cas_async run")]
    for thread in threads:
        thread.join(timeout=LIMIT)
    assert not any(t.is_alive() for t in threads)


async def test_cancelling_the_waiter_stops_the_run() -> None:
    scenario = load_scenario(
        FIRE_BRIGADE,
        ["run.virtual=true", 'run.transport="memory"', "mission.buckets=100000",
         "run.max_time=1000000"],
    )  # fmt: skip
    run = BackgroundRun(scenario)
    waiter = asyncio.ensure_future(run.wait())
    async with asyncio.timeout(LIMIT):
        while run.progress().time < 1.0:
            await asyncio.sleep(0.01)
        waiter.cancel()
        with pytest.raises(asyncio.CancelledError):
            await waiter
        while not run.done:
            await asyncio.sleep(0.01)
    assert run.progress().status is RunStatus.INTERRUPTED
