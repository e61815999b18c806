"""A run with a network latency on virtual time, in one process: its windows, what it measures."""

from __future__ import annotations

import asyncio
import dataclasses
import math
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import cas_async
from cas_async import ConfigurationError, VirtualClock
from cas_async.scenario import (
    DEFAULT_LATENCY,
    RunResult,
    RunStatus,
    Scenario,
    ScenarioError,
    ScenarioRun,
    load_scenario,
)
from cas_async.scenario._processes._windows import Windows
from cas_async.scenario._run import _windowed as windowed
from cas_async.sim import Environment
from cas_async.testing import ScenarioOutcome, run_scenario_file

SCENARIO = Path(__file__).resolve().parents[2] / "apps" / "fire_brigade" / "scenarios"
SMALL = (SCENARIO / "thesis_5_8_1.toml", "mission.buckets=4")
VIRTUAL = ("run.virtual=true", 'run.transport="memory"')


class RecordingWindows(Windows):
    """Windows that note every window they close: how, its end, the next event, what followed."""

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        first_end: float,
        close: Callable[[float, float], Awaitable[float | None]],
        failed: Callable[[], None] = lambda: None,
        idle: Callable[[], None] = lambda: None,
        quick: Callable[[float, float], float | None] | None = None,
    ) -> None:
        self.closed_windows: list[tuple[str, float, float, float | None]] = []
        self.first_end = first_end

        async def noted_close(end: float, next_event: float) -> float | None:
            following = await close(end, next_event)
            self.closed_windows.append(("close", end, next_event, following))
            return following

        def noted_quick(end: float, next_event: float) -> float | None:
            assert quick is not None
            following = quick(end, next_event)
            if following is not None:
                self.closed_windows.append(("quick", end, next_event, following))
            return following

        super().__init__(
            loop, first_end, noted_close, failed, idle, None if quick is None else noted_quick
        )


@pytest.fixture
def recorded(monkeypatch: pytest.MonkeyPatch) -> list[RecordingWindows]:
    """The windows of the runs of the test, as they closed."""
    made: list[RecordingWindows] = []

    class Noted(RecordingWindows):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(windowed, "Windows", Noted)
    return made


@pytest.fixture
def robots_worlds(monkeypatch: pytest.MonkeyPatch) -> list[Environment]:
    """The Environments the robots of the test's runs move in (not the mirrors the runs read)."""
    made: list[Environment] = []
    build = Scenario.environment

    def environment(self: Scenario, clock: Any) -> Environment:
        env = build(self, clock)
        made.append(env)
        return env

    monkeypatch.setattr(Scenario, "environment", environment)
    return made


def measured(result: RunResult) -> dict[str, Any]:
    """What a run measured, but the wall time."""
    figures = dataclasses.asdict(result)
    figures.pop("wall_time")
    return figures


def run_small(*overrides: str) -> ScenarioOutcome:
    return run_scenario_file(SMALL[0], SMALL[1], *overrides)


def test_a_run_with_the_default_latency_moves_in_windows(
    recorded: list[RecordingWindows],
) -> None:
    outcome = run_small()
    result = outcome.result
    assert result.status is RunStatus.COMPLETED
    assert outcome.environment.latency == 0.0  # what the run reads: the mirror
    (windows,) = recorded
    assert windows.first_end == DEFAULT_LATENCY
    assert result.extra["windows"] == windows.rounds == len(windows.closed_windows)
    ends = [end for _, end, _, _ in windows.closed_windows]
    assert ends[0] == DEFAULT_LATENCY
    # A window ends L after the first event at or after the previous end, or at the
    # next step (every run.credit, ten latencies by default) if that comes first.
    step = 10 * DEFAULT_LATENCY
    steps = 0
    for (_, end, next_event, following), later in zip(
        windows.closed_windows, ends[1:], strict=False
    ):
        assert next_event >= end
        if end == (steps + 1) * step:
            steps += 1
        assert following == later == min(next_event + DEFAULT_LATENCY, (steps + 1) * step)
    assert steps > 10
    assert result.makespan is not None
    assert 10 < windows.rounds <= result.makespan / DEFAULT_LATENCY + 2


def test_a_run_goes_on_to_the_end_of_the_step_after_its_completion(
    recorded: list[RecordingWindows], robots_worlds: list[Environment]
) -> None:
    outcome = run_small()
    makespan = outcome.result.makespan
    assert makespan is not None
    step = 10 * DEFAULT_LATENCY  # run.credit's default: ten latencies
    ends_at = (math.floor(makespan / step) + 2) * step  # the step after the completion's
    closed = recorded[0].closed_windows
    how, last_end, next_event, following = closed[-1]
    assert (how, following) == ("close", None)
    # The windows stop there, or where nothing happens before it any more.
    assert last_end == pytest.approx(ends_at, abs=1e-12) or next_event >= ends_at - 1e-12
    # The robots ran every event before it, and none at or past it.
    (robots,) = robots_worlds
    times = [event.t for event in robots.items.events]
    assert max(times) < ends_at
    assert max(times) > makespan  # they did go on past the completion
    # ...but what the run measured ends at the completion.
    assert outcome.result.sim_time == makespan
    assert outcome.environment.items.events[-1].t <= makespan


def test_the_credit_is_a_scenario_key() -> None:
    makespan = run_small().result.makespan
    longer = run_small("run.credit=1.0")
    assert longer.result.makespan == makespan  # what the run measures does not change
    assert sum(longer.result.messages_external.values()) > 0
    with pytest.raises(ScenarioError, match=r"run\.credit: expected at least network\.latency"):
        run_small("run.credit=0.001")


def test_the_same_seed_gives_the_same_run() -> None:
    first, second = run_small("run.seed=7"), run_small("run.seed=7")
    assert measured(first.result) == measured(second.result)
    assert np.array_equal(first.trace.times, second.trace.times)
    assert np.array_equal(first.trace.positions, second.trace.positions)
    assert np.array_equal(first.trace.carrying, second.trace.carrying)
    other = run_small("run.seed=8")
    assert measured(other.result) != measured(first.result)


def test_samples_come_at_every_interval_until_the_completion() -> None:
    outcome = run_small("run.trace_interval=0.5")
    makespan = outcome.result.makespan
    assert makespan is not None
    times = outcome.trace.times.tolist()
    ticks = [k * 0.5 for k in range(math.ceil(makespan / 0.5))]
    assert times == [*ticks, makespan]  # the last one at the completion


def test_a_run_that_times_out_is_measured_at_max_time(recorded: list[RecordingWindows]) -> None:
    outcome = run_small("run.max_time=3.0")
    result = outcome.result
    assert (result.status, result.sim_time, result.makespan) == (RunStatus.TIMED_OUT, 3.0, None)
    assert outcome.trace.times.tolist() == [0.0, 1.0, 2.0]
    assert result.extra["windows"] == recorded[0].rounds > 0


def test_a_scenario_without_latency_runs_without_windows(
    recorded: list[RecordingWindows], robots_worlds: list[Environment]
) -> None:
    outcome = run_small("network.latency=0")
    assert outcome.result.status is RunStatus.COMPLETED
    assert "windows" not in outcome.result.extra
    assert recorded == []
    (robots,) = robots_worlds
    assert robots.latency == 0.0
    assert outcome.environment is robots  # no mirror: the run reads the robots' world
    with_latency = run_small()
    assert with_latency.result.makespan != outcome.result.makespan


@pytest.mark.parametrize("at", [6.0, 5.4025], ids=["on-a-tick", "mid-window"])
def test_an_interrupted_run_is_measured_where_it_stands(
    at: float, robots_worlds: list[Environment]
) -> None:
    scenario = load_scenario(SMALL[0], [*VIRTUAL, SMALL[1]])

    async def interrupted() -> ScenarioRun:
        run = ScenarioRun(scenario)
        async with run:
            asyncio.get_running_loop().call_at(at, run.interrupt)
            await run.until_done()
        return run

    run = cas_async.run(interrupted(), virtual=True)
    result = run.result
    assert (result.status, result.sim_time) == (RunStatus.INTERRUPTED, at)
    # The mirror holds every item event the robots had by then, and measures them.
    (robots,) = robots_worlds
    before = [(event.t, event.kind, event.item) for event in robots.items.events if event.t <= at]
    assert [(e.t, e.kind, e.item) for e in run.environment.items.events] == before
    retired = [event for event in robots.items.events if event.kind.value == "retired"]
    assert (
        result.delivered
        == run.environment.items.retired
        == len([event for event in retired if event.t <= at])
    )
    assert result.delivered >= 2


async def test_windows_need_the_virtual_time_loop() -> None:
    scenario = load_scenario(SMALL[0], [*VIRTUAL, SMALL[1]])
    clock = VirtualClock()
    env = scenario.environment(clock)

    async def sample(t: float) -> None:
        pass

    run = windowed.WindowedRun(scenario, env, clock, sample, lambda: False)
    with pytest.raises(ConfigurationError, match=r"needs the virtual-time loop"):
        run.start()
    assert (run.rounds, run.failure, run.observed_until) == (0, None, 0.0)
