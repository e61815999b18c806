"""A run step by step (ScenarioRun): build, start, until done, measured before the robots stop."""

from __future__ import annotations

import asyncio
import gc
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

import cas_async
from cas_async import RobotState
from cas_async.scenario import RunStatus, ScenarioRun, load_scenario, run_scenario
from cas_async.sim import Environment, ItemEvent, ItemEventKind
from tests.fire_brigade.helpers import SCENARIOS, VIRTUAL

SHIPPED = SCENARIOS / "thesis_5_8_1.toml"


def test_the_steps_measure_what_run_scenario_measures() -> None:
    scenario = load_scenario(SHIPPED, [*VIRTUAL, "run.seed=4"])
    whole, _ = cas_async.run(run_scenario(scenario), virtual=True)

    async def stepwise() -> ScenarioRun:
        run = ScenarioRun(scenario)
        async with run:
            result = await run.until_done()
            assert result is run.result
            measured = result.wall_time
            await asyncio.sleep(5.0)  # virtual: what the caller does here is not the run's
            assert all(robot.state is RobotState.RUNNING for robot in run.swarm)
        assert all(robot.state is RobotState.STOPPED for robot in run.swarm)
        assert run.result.wall_time == measured  # nor is stopping the robots
        return run

    run = cas_async.run(stepwise(), virtual=True)
    assert run.result.status is RunStatus.COMPLETED
    assert (run.result.makespan, run.result.exchanges) == (whole.makespan, whole.exchanges)
    assert run.result.messages_external == whole.messages_external


def test_interrupt_ends_the_run_at_once_with_what_it_measured() -> None:
    scenario = load_scenario(SHIPPED, VIRTUAL)

    async def interrupted() -> ScenarioRun:
        run = ScenarioRun(scenario)
        async with run:
            loop = asyncio.get_running_loop()
            # A loop callback at simulated t = 5, as the command line schedules on a signal.
            loop.call_at(5.0, run.interrupt)
            result = await run.until_done()
            assert result.sim_time == 5.0  # measured in the callback, not when the task woke
            assert result.status is RunStatus.INTERRUPTED
        return run

    run = cas_async.run(interrupted(), virtual=True)
    assert run.result.status is RunStatus.INTERRUPTED
    assert run.result.exchanges > 0
    assert run.result.makespan is None


def test_a_stop_while_the_robots_open_undoes_the_start() -> None:
    # UDP sockets open one await at a time: a stop set beforehand lands mid-start.
    scenario = load_scenario(SHIPPED)
    stop = asyncio.Event()
    stop.set()

    async def stopped() -> ScenarioRun:
        run = ScenarioRun(scenario, stop=stop)
        async with run:
            result = await run.until_done()
        assert result.status is RunStatus.INTERRUPTED
        assert result.sim_time < 1.0
        return run

    run = cas_async.run(stopped())
    states = {robot.state for robot in run.swarm}
    assert states <= {RobotState.CREATED, RobotState.STOPPED}  # no socket left open
    assert RobotState.CREATED in states  # the start was cut short


def test_the_trace_file_is_written_as_the_run_goes_and_in_place_when_it_ends(
    tmp_path: Path,
) -> None:
    scenario = load_scenario(SHIPPED, VIRTUAL)
    path = tmp_path / "trace.csv"
    seen: dict[str, object] = {}

    def look() -> None:
        (partial,) = tmp_path.glob(".trace.csv.*.tmp")
        seen["rows at t = 10"] = partial.read_text().count("\n")
        seen["in place at t = 10"] = path.exists()

    async def traced() -> ScenarioRun:
        run = ScenarioRun(scenario, trace_csv=path)
        async with run:
            asyncio.get_running_loop().call_at(10.0, look)  # simulated t = 10
            assert run.trace_csv is None
            await run.until_done()
            assert run.trace_csv == path  # before the robots stop
        return run

    run = cas_async.run(traced(), virtual=True)
    rows = path.read_text().count("\n")
    assert seen["in place at t = 10"] is False
    assert isinstance(seen["rows at t = 10"], int)
    assert 1 < seen["rows at t = 10"] < rows
    assert rows == 1 + len(run.trace.ids) * (len(run.trace.times) + len(run.trace.exchange_times))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trace.csv"]


def test_a_run_that_never_started_writes_no_trace(tmp_path: Path) -> None:
    scenario = load_scenario(SHIPPED)
    stop = asyncio.Event()
    stop.set()

    async def stopped() -> None:
        run = ScenarioRun(scenario, stop=stop, trace_csv=tmp_path / "trace.csv")
        async with run:
            await run.until_done()
            assert run.trace_csv is None

    cas_async.run(stopped())
    assert list(tmp_path.iterdir()) == []


def test_a_start_that_fails_undoes_what_it_did(tmp_path: Path) -> None:
    # The trace file cannot be made: the robots had started, and must be stopped.
    scenario = load_scenario(SHIPPED, VIRTUAL)
    thresholds = gc.get_threshold()

    async def failing() -> ScenarioRun:
        run = ScenarioRun(scenario, trace_csv=tmp_path / "missing" / "trace.csv")
        with pytest.raises(FileNotFoundError):
            async with run:
                raise AssertionError("not reached")
        return run

    run = cas_async.run(failing(), virtual=True)
    assert {robot.state for robot in run.swarm} == {RobotState.STOPPED}
    assert gc.get_threshold() == thresholds


def test_the_missions_measures_are_evaluated_on_every_sample_and_snapshot() -> None:
    scenario = load_scenario(SHIPPED, [*VIRTUAL, "run.seed=2", "mission.buckets=4"])

    async def measured() -> tuple[ScenarioRun, list[int]]:
        run = ScenarioRun(scenario)
        seen: list[int] = []

        def spread(ids: Sequence[int], xy: npt.NDArray[np.float64]) -> float:
            seen.append(len(ids))
            return float(np.ptp(xy[:, 0]))  # how wide the swarm stands

        run.mission.measures = {"spread": spread}
        async with run:
            await run.until_done()
        return run, seen

    run, seen = cas_async.run(measured(), virtual=True)
    result, trace = run.result, run.trace
    assert set(seen) == {len(trace.ids)}
    series, by_exchange = result.series["spread"], result.by_exchange["spread"]
    assert series["t"] == trace.times.tolist()
    assert series["value"] == [float(np.ptp(xy[:, 0])) for xy in trace.positions]
    assert by_exchange["count"] == [float(n) for n in trace.exchange_counts.tolist()]
    assert len(by_exchange["value"]) == result.exchanges > 0
    late = [
        v for t, v in zip(series["t"], series["value"], strict=True) if t >= result.sim_time * 2 / 3
    ]
    assert result.metrics == {"spread": pytest.approx(sum(late) / len(late))}
    assert result.scalars()["spread"] == result.metrics["spread"]
    # the carriers of each record are the ledger's holders: every exchange has one
    assert all(trace.exchange_carrying.any(axis=1))
    assert result.delivery_times == sorted(result.delivery_times)
    assert len(result.delivery_times) == result.delivered == 4
    assert result.delivery_times[-1] == result.makespan


def test_items_retired_after_the_target_are_not_the_runs() -> None:
    # On scaled time another delivery may come before the loop gets round to ending the
    # run: it is not counted. Here one comes in the very callback of the last delivery.
    scenario = load_scenario(SHIPPED, [*VIRTUAL, "run.seed=3", "mission.buckets=3"])
    late: list[int] = []

    def observe(environment: Environment) -> None:
        ledger = environment.items

        def one_more(event: ItemEvent) -> None:
            if event.kind is ItemEventKind.RETIRED and ledger.retired == 3 and not late:
                late.append(ledger.create(event.robot, event.t))
                ledger.retire(late[0], event.robot, event.t)

        ledger.subscribe(one_more)

    result, trace = cas_async.run(run_scenario(scenario, observe=observe), virtual=True)
    assert late
    assert result.delivered == 3
    assert len(result.delivery_times) == len(result.travel_times) == 3
    assert late[0] > result.created  # the item made after the end is not counted either
    assert result.exchanges == trace.exchange_counts[-1]
