"""What a sweep shows while it runs: a bar on a terminal, a line per run elsewhere; a fake clock."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from cas_async.scenario import RunStatus
from cas_async.scenario.sweeps import SweepOutcome, SweepPlan, SweepRun, plan_sweep
from cas_async.scenario.sweeps._display import SweepDisplay, last_line
from tests.scenario.sweep_apps import scenario


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def plan(tmp_path: Path) -> SweepPlan:
    return plan_sweep(scenario(tmp_path), seeds=5, vary=["trouble.mode=none,raise"])


def _run(seed: int, status: RunStatus = RunStatus.COMPLETED) -> SweepRun:
    error = None if status is RunStatus.COMPLETED else "RuntimeError: no"
    return SweepRun(0, seed, status, error, {"makespan": 2.5, "wall_time": 0.25})


def _screen(text: str) -> list[str]:
    """What a terminal shows: each line as the last ``\\r`` left it."""
    return [line.rsplit("\r", 1)[-1].rstrip() for line in text.split("\n")]


def test_on_a_terminal_a_bar_counts_done_failed_running_and_the_time_left(
    plan: SweepPlan,
) -> None:
    stream, clock = io.StringIO(), Clock()
    display = SweepDisplay(stream, plan, tty=True, now=clock)
    display.update(running=2, workers=2)
    assert _screen(stream.getvalue()) == [
        "[--------------------] 0/10 runs | 0 failed | 2 running | 2 workers | -:-- left"
    ]
    clock.now = 4.0
    display.finished(_run(1), running=2, workers=2)
    display.finished(_run(2, RunStatus.FAILED), running=2, workers=2)
    assert _screen(stream.getvalue()) == [
        "trouble.mode=none seed 2: failed: RuntimeError: no (wall 0.25 s)",  # above the bar
        # 2 of 10 in 4 s: 8 more take 16 s
        "[####----------------] 2/10 runs | 1 failed | 2 running | 2 workers | 0:16 left",
    ]


def test_the_bar_is_redrawn_ten_times_a_second_at_most(plan: SweepPlan) -> None:
    stream, clock = io.StringIO(), Clock()
    display = SweepDisplay(stream, plan, tty=True, now=clock)
    display.update(running=1, workers=None)
    drawn = stream.getvalue().count("\r")
    clock.now = 0.05
    display.update(running=1, workers=None)
    assert stream.getvalue().count("\r") == drawn
    clock.now = 0.15
    display.update(running=1, workers=None)
    assert stream.getvalue().count("\r") > drawn
    assert "workers" not in stream.getvalue()  # a pool's workers are not news


def test_hours_left_are_shown_as_hours(plan: SweepPlan) -> None:
    stream, clock = io.StringIO(), Clock()
    display = SweepDisplay(stream, plan, tty=True, now=clock)
    clock.now = 1000.0
    display.finished(_run(1), running=1, workers=None)
    assert _screen(stream.getvalue())[-1].endswith("| 2:30:00 left")


def test_elsewhere_each_finished_run_is_a_plain_line(plan: SweepPlan) -> None:
    stream = io.StringIO()
    display = SweepDisplay(stream, plan, tty=False, now=Clock())
    display.update(running=2, workers=2)  # nothing: a log gets a line per run
    display.finished(_run(3), running=1, workers=2)
    display.finished(_run(4, RunStatus.TIMED_OUT), running=0, workers=2)
    assert stream.getvalue().splitlines() == [
        "[1/10] trouble.mode=none seed 3: completed, makespan 2.50 s (wall 0.25 s)",
        "[2/10] trouble.mode=none seed 4: timed_out (wall 0.25 s)",
    ]
    assert "\r" not in stream.getvalue()


def test_a_resumed_sweep_counts_its_earlier_runs(plan: SweepPlan, tmp_path: Path) -> None:
    stream = io.StringIO()
    display = SweepDisplay(stream, plan, tty=False, now=Clock())
    display.resumed([_run(1), _run(2, RunStatus.FAILED)], tmp_path)
    display.finished(_run(3), running=0, workers=None)
    assert stream.getvalue().splitlines() == [
        f"resuming: 2 of 10 runs done in {tmp_path}/, 8 to run",
        "[3/10] trouble.mode=none seed 3: completed, makespan 2.50 s (wall 0.25 s)",
    ]


@pytest.mark.parametrize(
    ("fields", "line"),
    [
        pytest.param(
            {},
            "sweep: 3 runs (1 completed, 1 failed, 1 timed out) in 2.0 s wall, 2 worker processes",
            id="local",
        ),
        pytest.param(
            {
                "ran_on": "2 Dask workers at tcp://10.0.0.5:8786",
                "workers_lost": 1,
                "runs_resent": 2,
                "resumed": 1,
            },
            "sweep: 3 runs (1 completed, 1 failed, 1 timed out; 1 resumed; 1 worker lost, "
            "2 runs sent again) in 2.0 s wall, 2 Dask workers at tcp://10.0.0.5:8786",
            id="cluster",
        ),
        pytest.param(
            {"interrupted": True, "error": "lost the connection"},
            "sweep: interrupted after 3 of 10 runs (1 completed, 1 failed, 1 timed out) "
            "in 2.0 s wall, 2 worker processes",
            id="cut-short",
        ),
    ],
)
def test_the_last_line_counts_what_became_of_the_runs(
    plan: SweepPlan, fields: dict[str, object], line: str
) -> None:
    runs = (_run(1), _run(2, RunStatus.FAILED), _run(3, RunStatus.TIMED_OUT))
    outcome = SweepOutcome(plan, runs, 2.0, 2, **fields)  # type: ignore[arg-type]
    assert last_line(outcome) == line
