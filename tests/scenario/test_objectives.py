"""The Objective interface as the runner uses it: end, progress, audit, carrying, results, figures.

Most tests run the toy app of ``tests/scenario/objective_apps.py``: three robots do
chores at 1.1, 1.2, 1.3, 2.1, 2.2, ... simulated seconds, and its objective
(:class:`ChoreCount`) is complete at the ``target``-th.
"""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import cas_async
from cas_async import ConfigurationError, Pose, VirtualClock
from cas_async.scenario import (
    Items,
    Mission,
    RunResult,
    RunStatus,
    Scenario,
    ScenarioRun,
    Tally,
    load_scenario,
)
from cas_async.scenario.output import Progress, results_dict, summary_table
from cas_async.sim import Environment
from tests.scenario.objective_apps import ChoreCount

ROOT = Path(__file__).resolve().parents[2]

SCENARIO = """\
app = "tests.scenario.objective_apps"

[run]
virtual = true
transport = "memory"
max_time = 10.0
trace_interval = 1.0
progress_interval = 1.0

[world]
width = 10.0
height = 10.0

[chores]
"""


Load = Callable[..., Scenario]


@pytest.fixture
def chores(tmp_path: Path) -> Load:
    """``chores(target=5, ...)``: the toy scenario with those ``[chores]`` keys, loaded."""

    def load(**keys: object) -> Scenario:
        path = tmp_path / "chores.toml"
        table = "".join(f"{key} = {json.dumps(value)}\n" for key, value in keys.items())
        path.write_text(SCENARIO + table)
        return load_scenario(path)

    return load


def run(scenario: Scenario, **options: Any) -> ScenarioRun:
    """Runs ``scenario`` to its end on virtual time (``ScenarioRun`` options); returns the run."""

    async def steps() -> ScenarioRun:
        scenario_run = ScenarioRun(scenario, **options)
        async with scenario_run:
            await scenario_run.until_done()
        return scenario_run

    finished: ScenarioRun = cas_async.run(steps(), virtual=True)
    return finished


def toy(scenario_run: ScenarioRun) -> ChoreCount:
    objective = scenario_run.objective
    assert isinstance(objective, ChoreCount)
    return objective


# -- the end of a run ----------------------------------------------------------------------


def test_completion_ends_the_run_with_the_instant_given_as_makespan(chores: Load) -> None:
    scenario_run = run(chores(target=5))
    result, objective = scenario_run.result, toy(scenario_run)
    assert result.status is RunStatus.COMPLETED
    assert objective.completions[0] == pytest.approx(2.2)  # the 5th chore
    assert result.makespan == objective.completions[0]
    assert result.sim_time == result.makespan == objective.measured_at
    assert result.delivered == result.target == 5


def test_calls_after_the_end_are_ignored(chores: Load) -> None:
    stream = io.StringIO()
    scenario_run = run(chores(target=2), progress_to=stream)
    watch, result = toy(scenario_run).watch, scenario_run.result
    assert watch is not None
    shown, exchanges = stream.getvalue(), len(scenario_run.trace.exchange_counts)
    watch.completed(9.0)
    watch.changed(9.0)
    watch.exchanged(9.0, 99)
    assert result.makespan == pytest.approx(1.2)
    assert stream.getvalue() == shown
    assert len(scenario_run.trace.exchange_counts) == exchanges


def test_a_target_out_of_reach_times_out(chores: Load) -> None:
    result = run(chores(target=10)).result  # 3 robots x 3 chores
    assert result.status is RunStatus.TIMED_OUT
    assert (result.makespan, result.sim_time, result.delivered) == (None, 10.0, 9)


def test_a_failing_audit_fails_the_run_at_its_sample(chores: Load) -> None:
    result = run(chores(target=5, audit_fails_at=1.5)).result
    assert result.status is RunStatus.FAILED
    assert result.error == "audit failed at t=2: the board disagrees with itself"
    assert result.traceback is not None
    assert "RuntimeError" in result.traceback
    assert result.makespan is None
    assert result.sim_time == 2.0


# -- what the trace shows -------------------------------------------------------------------


def test_carrying_marks_the_robots_in_the_trace(chores: Load) -> None:
    scenario_run = run(chores(target=5))
    trace = scenario_run.trace
    makespan = scenario_run.result.makespan
    assert makespan is not None
    # The samples every second, and one where the mission was complete.
    assert trace.times.tolist() == [0.0, 1.0, 2.0, makespan]
    # Each robot is "busy" from its first chore (1.1, 1.2, 1.3) on.
    assert trace.carrying.tolist() == [[False] * 3, [False] * 3, [True] * 3, [True] * 3]


def test_exchanges_reported_by_an_objective_are_snapshotted(chores: Load) -> None:
    trace = run(chores(target=5)).trace
    assert trace.exchange_counts.tolist() == [1, 2, 3, 4, 5]
    assert trace.exchange_times.tolist() == pytest.approx([1.1, 1.2, 1.3, 2.1, 2.2])


# -- what the results hold ------------------------------------------------------------------


def test_measured_samples_and_extras_are_in_results_json(chores: Load) -> None:
    data = results_dict(run(chores(target=5)).result)
    assert (data["kind"], data["verb"], data["item_name"]) == ("chores", "done", "chore")
    assert (data["delivered"], data["target"]) == (5, 5)
    assert data["samples"]["chore_time"] == pytest.approx([1.1, 1.2, 1.3, 2.1, 2.2])
    assert data["statistics"]["chore_time"]["count"] == 5
    assert data["statistics"]["gap"]["max"] == pytest.approx(1.1)
    assert data["extra"] == {"busy_robots": 3, "label": "toy"}
    assert data["delivery_times"] == data["samples"]["chore_time"]
    items_only = {"created", "exchanges", "travel_times", "handovers_per_item"}
    assert items_only.isdisjoint(data)
    assert {"travel_time", "handovers_per_item"}.isdisjoint(data["statistics"])
    json.dumps(data)  # plain data


def test_the_summary_table_counts_with_the_objective_s_words(chores: Load) -> None:
    table = summary_table(run(chores(target=5)).result)
    assert table.startswith("Chores — ")
    assert re.search(r"^chores done +5 of 5$", table, re.M), table
    assert re.search(r"^chore time +mean 1\.6  median 1\.3  max 2\.2$", table, re.M), table
    assert re.search(r"^gap +mean 0\.4  median 0\.1  max 1\.1$", table, re.M), table
    assert re.search(r"^chores done by +0\.6 s: 0, 1\.1 s: 1, 1\.7 s: 3, 2\.2 s: 5$", table, re.M)
    assert re.search(r"^busy robots +3$", table, re.M)
    assert "exchanges" not in table
    assert "travel time" not in table


def test_scalars_hold_each_sample_s_mean_and_no_exchanges(chores: Load) -> None:
    scalars = run(chores(target=5)).result.scalars()
    assert scalars["chore_time"] == pytest.approx(1.58)
    assert scalars["gap"] == pytest.approx(0.44)
    assert scalars["delivered"] == 5.0
    assert scalars["busy_robots"] == 3.0
    assert "exchanges" not in scalars
    assert "travel_time" not in scalars


# -- the app's measuring fails the run, never the summary ---------------------------------------


def test_a_value_that_is_not_one_figure_fails_the_run_with_one_line(chores: Load) -> None:
    result = run(chores(target=5, measure_fails="extra")).result
    assert result.status is RunStatus.FAILED
    assert result.error == (
        "RunResult.extra['by_robot'] = {1: 1, 2: 1, 3: 1}: not one figure (dict); an extra "
        "value is a number (int, float), a str or a bool (values per thing done go in "
        "RunResult.samples)"
    )
    assert result.traceback is None  # the line says it all
    assert result.makespan == pytest.approx(2.2)  # what was measured stays
    assert result.extra == {"busy_robots": 3}
    assert "error                 RunResult.extra['by_robot']" in summary_table(result)


def test_an_objective_that_raises_while_measuring_fails_the_run(chores: Load) -> None:
    result = run(chores(target=5, measure_fails="raises")).result
    assert result.status is RunStatus.FAILED
    assert result.error == (
        "ChoreCount.measure raised ZeroDivisionError: no chores per robot to divide"
    )
    assert result.traceback is not None
    assert "objective_apps.py" in result.traceback  # the app's line, to fix it
    assert (result.delivered, result.sim_time) == (5, pytest.approx(2.2))  # measured before


def test_mission_extra_that_returns_no_dict_fails_the_run(chores: Load) -> None:
    scenario_run = ScenarioRun(chores(target=5))
    scenario_run.mission.extra = lambda: [("a", 1)]  # type: ignore[assignment,return-value]

    async def steps() -> RunResult:
        async with scenario_run:
            return await scenario_run.until_done()

    result = cas_async.run(steps(), virtual=True)
    assert (result.status, result.traceback) == (RunStatus.FAILED, None)
    assert result.error == "Mission.extra returned a list, not a dict of figures by name"


def test_the_command_line_shows_the_refused_value_without_a_traceback(tmp_path: Path) -> None:
    from cas_async._cli._main import main

    scenario = tmp_path / "chores.toml"
    scenario.write_text(SCENARIO + 'target = 5\nmeasure_fails = "extra"\n')
    stdout, stderr = io.StringIO(), io.StringIO()
    out = tmp_path / "out"
    code = main(
        ["run", str(scenario), "--no-plots", "--out", str(out)], stdout=stdout, stderr=stderr
    )
    assert code == 1
    assert "Traceback" not in stderr.getvalue()  # progress lines only
    assert stdout.getvalue().splitlines()[:2] == [
        f"Chores — {scenario}, seed 0: FAILED",
        "error                 RunResult.extra['by_robot'] = {1: 1, 2: 1, 3: 1}: not one "
        "figure (dict); an extra value is a number (int, float), a str or a bool (values per "
        "thing done go in RunResult.samples)",
    ]
    results = json.loads((out / "results.json").read_text())
    assert (results["status"], results["extra"]) == ("failed", {"busy_robots": 3})


# -- the progress line ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("tty", "line"),
    [
        (False, "t=12.5s objects 2/3 joint carries 4\n"),
        (True, "\r[#############-------] 2/3 objects | t = 12.5 s | 4 joint carries"),
    ],
    ids=["plain", "tty"],
)
def test_progress_names_the_objective_s_noun_and_detail(tty: bool, line: str) -> None:
    stream = io.StringIO()
    progress = Progress(stream, target=3, item_name="object", detail="joint carries", tty=tty)
    progress.update(12.5, 2, 4)
    assert stream.getvalue() == line


def test_a_run_shows_its_progress_with_the_objective_s_words(chores: Load) -> None:
    stream = io.StringIO()
    run(chores(target=5), progress_to=stream)
    lines = stream.getvalue().splitlines()
    assert lines[0] == "t=0.0s chores 0/5 busy robots 0"
    assert lines[-1] == "t=2.2s chores 5/5 busy robots 3"


# -- what a mission may be -------------------------------------------------------------------


def test_a_mission_has_a_target_or_an_objective_not_both_nor_neither() -> None:
    objective = Items(1)
    with pytest.raises(ValueError, match="not both"):
        Mission([], target=1, objective=objective)
    with pytest.raises(ValueError, match="not neither"):
        Mission([])
    assert Mission([], objective=objective).objective is objective


def test_a_mission_of_its_own_is_refused_across_processes(chores: Load) -> None:
    pytest.importorskip("zenoh")  # a World needs it importable; nothing is started here
    from cas_async.scenario._processes._world import World

    scenario = chores(target=5)
    with pytest.raises(ConfigurationError, match="objective ChoreCount is not distributable"):
        ScenarioRun(scenario, world=World(scenario, workers=1, key=None, spawn=False))


# -- Items: the ready-made objective ---------------------------------------------------------


class RecordingWatch:
    """A :class:`~cas_async.scenario.Watch` that records what it is told."""

    def __init__(self, environment: Environment) -> None:
        self.environment = environment
        self.clock = VirtualClock()
        self.told: list[tuple[str, float] | tuple[str, float, int]] = []

    def changed(self, t: float) -> None:
        self.told.append(("changed", t))

    def completed(self, t: float) -> None:
        self.told.append(("completed", t))

    def exchanged(self, t: float, count: int) -> None:
        self.told.append(("exchanged", t, count))


def test_items_follows_the_item_ledger_up_to_its_target() -> None:
    environment = Environment()
    environment.add_robot(1, Pose(0.0, 0.0, 0.0))
    environment.add_robot(2, Pose(0.0, 0.0, 0.0))
    objective = Items(2, noun="bucket")
    assert (objective.target, objective.noun, objective.kind) == (2, "bucket", "items")
    assert objective.distributable
    watch = RecordingWatch(environment)
    objective.attach(watch)
    first = environment.create_item(1, 0.5)
    environment.hand_over(first, 1, 2, 1.0, reach=0.1)
    assert objective.carrying() == (2,)
    environment.retire_item(first, 2, 2.0)
    second = environment.create_item(1, 2.5)
    assert objective.progress() == Tally(1, 1)
    environment.retire_item(second, 1, 3.0)
    objective.check()
    assert objective.progress() == Tally(2, 1)
    after = environment.create_item(2, 3.5)  # past the target: not the run's
    environment.retire_item(after, 2, 4.0)
    assert watch.told == [
        ("changed", 0.5),
        ("exchanged", 1.0, 1),
        ("changed", 1.0),
        ("changed", 2.0),
        ("changed", 2.5),
        ("completed", 3.0),
        ("changed", 3.0),
    ]
    result = RunResult(scenario="s.toml", app="Brigade", item_name="bucket", seed=0)
    objective.measure(result, 4.0)
    assert (result.created, result.delivered, result.exchanges) == (2, 2, 1)
    assert result.delivery_times == [2.0, 3.0]
    assert result.travel_times == [1.5, 0.5]
    assert result.handovers_per_item == [1, 0]
    assert result.samples == {}


def test_items_refuses_a_negative_target_and_an_unattached_use() -> None:
    with pytest.raises(ValueError, match="must not be negative"):
        Items(-1)
    with pytest.raises(RuntimeError, match="not attached"):
        Items(1).progress()


# -- the objective's own figures -----------------------------------------------------------------


@pytest.mark.slow
def test_the_command_line_writes_the_objective_s_figures(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    scenario = tmp_path / "chores.toml"
    scenario.write_text(SCENARIO + "target = 4\nfigure = true\n")
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-m", "cas_async", "run", str(scenario), "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    written = re.search(r"^wrote (.*) to ", done.stdout, re.M)
    assert written, done.stdout
    names = written.group(1).split(", ")
    assert names[:2] == ["results.json", "trace.csv"]
    assert names[-1] == "chores.txt"  # after the runner's figures
    assert "over_time.png" in names
    # samples at 0, 1 and 2 s, and where the fourth chore completed the mission
    assert (out / "chores.txt").read_text() == "samples 4\n1 1.1\n2 1.2\n3 1.3\n1 2.1\n"
