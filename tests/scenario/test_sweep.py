"""``python -m cas_async sweep``: a scenario over a grid of values and seeds.

The command line runs as a user runs it (a real subprocess, helpers of
``tests/test_cli.py``) on a small grid of fast runs; the pure parts (reading
``--vary``, the statistics, the numbers and the table) are tested in process.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import math
import os
import re
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Final

import pytest

from cas_async.scenario import RunStatus, ScenarioError, load_scenario
from cas_async.scenario.sweeps import (
    MetricStats,
    SweepOutcome,
    SweepPlan,
    SweepRun,
    parse_vary,
    plan_sweep,
    run_sweep,
    sweep,
    sweep_table,
)
from cas_async.scenario.sweeps._files import format_number
from cas_async.scenario.sweeps._outcome import summarise
from cas_async.scenario.sweeps._plan import SWEEP_DEFAULTS
from tests.scenario.sweep_apps import scenario
from tests.test_cli import (
    _ENV,
    PNG_MAGIC,
    ROOT,
    RUN_LIMIT,
    SCENARIOS,
    STOP_LIMIT,
    Finished,
    _first_line,
    run_cli,
    start_cli,
)

SMALL: Final = SCENARIOS / "thesis_5_8_1.toml"
SLOW: Final = SCENARIOS / "thesis_5_8_2.toml"
"""25 robots, 20 buckets: about a wall second a run."""
GRID: Final = ("--seeds", "2", "--vary", "strategy.name=time,solo", "--set", "mission.buckets=3")
CRASHING: Final = "tests.fire_brigade.crashing:CrashOnce"
FIGURES: Final = ("mean", "std", "min", "median", "max")


def read_csv(out: Path) -> list[dict[str, str]]:
    with (out / "runs.csv").open(encoding="utf-8", newline="") as stream:
        return list(csv.DictReader(stream))


def read_table(out: Path) -> tuple[list[str], list[list[str]]]:
    """``table.md``'s header and rows, cells stripped."""
    lines = [line for line in (out / "table.md").read_text("utf-8").splitlines() if line[:1] == "|"]
    header, _rule, *rows = ([cell.strip() for cell in line.strip("|").split("|")] for line in lines)
    return header, rows


# -- a small sweep, end to end -----------------------------------------------------------


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory: pytest.TempPathFactory) -> tuple[Finished, Path]:
    """2 strategies x 2 seeds of 3 buckets on two workers, shared by the tests that read it."""
    out = tmp_path_factory.mktemp("sweep") / "out"
    return run_cli("sweep", SMALL, *GRID, "--jobs", "2", "--out", out), out


@pytest.mark.slow
def test_a_sweep_exits_0_and_prints_its_table(small_sweep: tuple[Finished, Path]) -> None:
    finished, out = small_sweep
    assert finished.code == 0, finished.stderr
    table = (out / "table.md").read_text("utf-8")
    assert table.startswith(
        "Sweep of thesis_5_8_1.toml (--set mission.buckets=3), seeds 1-2, 2 grid points: "
        "4 runs, all completed. Figures are over the completed runs only;"
    )
    assert finished.stdout.startswith(table)
    assert finished.stdout.endswith(f" to {out}/\n")


@pytest.mark.slow
def test_each_finished_run_is_a_progress_line(small_sweep: tuple[Finished, Path]) -> None:
    finished, _ = small_sweep
    *runs, last = finished.stderr.splitlines()
    assert len(runs) == 4, finished.stderr
    for k, line in enumerate(runs, start=1):
        assert re.fullmatch(
            rf"\[{k}/4\] strategy\.name=(time|solo) seed [12]: completed, "
            r"makespan [\d.]+ s \(wall [\d.]+ s\)",
            line,
        ), line
    assert re.fullmatch(r"sweep: 4 runs \(4 completed\) in [\d.]+ s wall, 2 worker processes", last)


@pytest.mark.slow
def test_runs_csv_has_a_row_per_run_and_a_column_per_metric(
    small_sweep: tuple[Finished, Path],
) -> None:
    _, out = small_sweep
    rows = read_csv(out)
    assert [(row["strategy.name"], row["seed"]) for row in rows] == [
        ("time", "1"),
        ("time", "2"),
        ("solo", "1"),
        ("solo", "2"),
    ]
    columns = list(rows[0])
    assert columns[:4] == ["strategy.name", "seed", "status", "error"]
    assert {"makespan", "exchanges_per_item", "delivered", "wall_time"} <= set(columns[4:])
    assert {row["status"] for row in rows} == {"completed"}
    assert {row["error"] for row in rows} == {""}
    assert {float(row["delivered"]) for row in rows} == {3.0}


@pytest.mark.slow
def test_the_table_s_figures_are_those_of_runs_csv(small_sweep: tuple[Finished, Path]) -> None:
    _, out = small_sweep
    rows = read_csv(out)
    header, table = read_table(out)
    assert header == ["strategy.name", "metric", "runs", *FIGURES]
    metrics = list(rows[0])[4:]
    assert [(row[1], row[0]) for row in table] == [
        (metric, strategy) for metric in metrics for strategy in ("time", "solo")
    ]
    for strategy, metric, runs, *figures in table:
        values = [float(row[metric]) for row in rows if row["strategy.name"] == strategy]
        assert runs == "2/2"
        expected = [
            statistics.fmean(values),
            statistics.stdev(values),
            min(values),
            statistics.median(values),
            max(values),
        ]
        assert figures == [format_number(value) for value in expected], (strategy, metric)


@pytest.mark.slow
def test_summary_json_has_the_unrounded_figures(small_sweep: tuple[Finished, Path]) -> None:
    _, out = small_sweep
    summary = json.loads((out / "summary.json").read_text("utf-8"))
    rows = read_csv(out)
    assert summary["vary"] == {"strategy.name": ["time", "solo"]}
    assert (summary["runs"], summary["completed"], summary["interrupted"]) == (4, 4, False)
    assert summary["incomplete"] == []
    for point in summary["points"]:
        strategy = point["values"]["strategy.name"]
        spans = [float(row["makespan"]) for row in rows if row["strategy.name"] == strategy]
        figures = point["metrics"]["makespan"]
        assert figures["n"] == 2
        assert figures["mean"] == pytest.approx(statistics.fmean(spans))
        assert figures["median"] == pytest.approx(statistics.median(spans))
        assert figures["std"] == pytest.approx(statistics.stdev(spans))


@pytest.mark.slow
def test_each_metric_has_a_box_plot(small_sweep: tuple[Finished, Path]) -> None:
    _, out = small_sweep
    metrics = list(read_csv(out)[0])[4:]
    names = sorted(path.name for path in out.glob("*.png"))
    assert names == sorted(f"box_{metric}.png" for metric in metrics)
    assert {"box_makespan.png", "box_exchanges_per_item.png"} <= set(names)
    for name in names:
        assert (out / name).read_bytes().startswith(PNG_MAGIC)
    assert not [path.name for path in out.iterdir() if path.name.startswith(".")]


# -- refused before any run ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "says"),
    [
        pytest.param(["--vary", "strategy.nam=time,solo"], "unknown key 'nam'", id="unknown-key"),
        pytest.param(
            ["--vary", "strategy.name=time,bogus"],
            "strategy.name: expected one of",
            id="bad-value",
        ),
        pytest.param(["--set", "mission.bucket=3"], "unknown key 'bucket'", id="bad-set"),
        pytest.param(["--vary", "run.seed=1,2"], "--vary: run.seed is the sweep's own", id="seed"),
        pytest.param(["--set", "run.seed=4"], "--set: run.seed is the sweep's own", id="set-seed"),
        pytest.param(
            ["--vary", "strategy.name=time", "--vary", "strategy.name=solo"],
            "--vary: strategy.name is varied twice",
            id="key-twice",
        ),
        pytest.param(
            ["--vary", "strategy.name=time,time"], "value time is listed twice", id="value-twice"
        ),
        pytest.param(["--vary", "strategy.name="], "strategy.name: no values", id="no-values"),
        pytest.param(
            [
                "--vary",
                "transporters.speed=" + ",".join(map(str, range(1, 1001))),
                "--seeds",
                "200",
            ],
            "1000 values x 200 seeds = 200,000 runs",
            id="too-many-runs",
        ),
    ],
)
def test_a_wrong_sweep_exits_2_before_any_run(args: list[str], says: str, tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli("sweep", SMALL, "--seeds", "2", *args, "--out", out)  # a later one wins
    assert finished.code == 2, finished.stderr
    assert finished.stderr.startswith("error: "), finished.stderr
    assert says in finished.stderr
    assert "[1/" not in finished.stderr
    assert "Traceback" not in finished.stderr
    assert finished.stdout == ""
    assert not out.exists()


def test_a_wrong_value_names_the_file_the_key_and_the_point(tmp_path: Path) -> None:
    finished = run_cli(
        "sweep",
        SMALL,
        "--seeds",
        "2",
        "--vary",
        "transporters.speed=1,-2,fast",
        "--out",
        tmp_path / "out",
    )
    assert finished.code == 2
    assert finished.stderr.splitlines() == [
        f"error: {SMALL}: transporters.speed: expected a number > 0, got -2 "
        "(at transporters.speed=-2)",
        f'{SMALL}: transporters.speed: expected a number > 0, got "fast" (a string) '
        "(at transporters.speed=fast)",
    ]


@pytest.mark.parametrize(
    "args",
    [["--seeds", "0"], ["--seeds", "2", "--jobs", "0"], ["--seeds", "two"], []],
    ids=["seeds-0", "jobs-0", "seeds-not-a-number", "no-seeds"],
)
def test_a_wrong_count_exits_2_with_the_usage(args: list[str], tmp_path: Path) -> None:
    finished = run_cli("sweep", SMALL, *args, "--out", tmp_path / "out")
    assert finished.code == 2
    assert finished.stderr.startswith("usage: python -m cas_async sweep")
    assert "--seeds" in finished.stderr or "--jobs" in finished.stderr
    assert not (tmp_path / "out").exists()


# -- runs that do not complete ---------------------------------------------------------------


@pytest.mark.slow
def test_failed_runs_exit_1_are_left_out_of_the_figures_and_named(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli(
        "sweep",
        SMALL,
        "--seeds",
        "2",
        "--vary",
        f"strategy.name=time,{CRASHING}",
        "--set",
        "mission.buckets=3",
        "--out",
        out,
    )
    assert finished.code == 1, finished.stderr
    statuses = {(row["strategy.name"], row["seed"]): row["status"] for row in read_csv(out)}
    assert statuses == {
        ("time", "1"): "completed",
        ("time", "2"): "completed",
        (CRASHING, "1"): "failed",
        (CRASHING, "2"): "failed",
    }
    table = (out / "table.md").read_text("utf-8")
    assert "4 runs, 2 completed" in table
    assert table.endswith(
        f"Not in the figures: strategy.name={CRASHING} seed 1 (failed), "
        f"strategy.name={CRASHING} seed 2 (failed).\n"
    )
    _, rows = read_table(out)
    assert [row[2] for row in rows if row[:2] == [CRASHING, "makespan"]] == ["0/2"]
    summary = json.loads((out / "summary.json").read_text("utf-8"))
    assert [(run["seed"], run["status"]) for run in summary["incomplete"]] == [
        (1, "failed"),
        (2, "failed"),
    ]
    assert all("the strategy broke down" in run["error"] for run in summary["incomplete"])
    assert re.search(
        rf"strategy\.name={re.escape(CRASHING)} seed 1: failed: robot", finished.stderr
    )


@pytest.mark.slow
def test_timed_out_runs_exit_1_with_the_outputs_written(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli("sweep", SMALL, "--seeds", "2", "--set", "run.max_time=1", "--out", out)
    assert finished.code == 1, finished.stderr
    assert [row["status"] for row in read_csv(out)] == ["timed_out", "timed_out"]
    table = (out / "table.md").read_text("utf-8")
    assert "2 runs, 0 completed" in table
    assert "Not in the figures: seed 1 (timed_out), seed 2 (timed_out)." in table
    assert "seed 1: timed_out at 1 s" in finished.stderr
    assert not list(out.glob("*.png"))  # no completed run: nothing to draw


# -- a signal ------------------------------------------------------------------------------


def _workers(pid: int) -> list[int]:
    """The sweep's worker processes: the children of ``pid`` that multiprocessing spawned."""
    found = []
    for child in Path(f"/proc/{pid}/task/{pid}/children").read_text("ascii").split():
        with contextlib.suppress(FileNotFoundError, ProcessLookupError):  # it just ended
            if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
                found.append(int(child))
    return found


def _gone(pid: int) -> bool:
    """Whether process ``pid`` has ended (or only waits to be reaped)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text("ascii")
    except (FileNotFoundError, ProcessLookupError):
        return True
    return "\nState:\tZ" in status


@pytest.mark.slow
@pytest.mark.skipif(
    not Path(f"/proc/{os.getpid()}/task/{os.getpid()}/children").exists(), reason="reads /proc"
)
@pytest.mark.parametrize("target", ["process", "group"], ids=["to-the-sweep", "as-ctrl-c"])
def test_sigint_stops_a_long_sweep_at_once_and_writes_what_finished(
    target: str, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    args = ["--seeds", "20", "--vary", "strategy.name=time,random", "--jobs", "2", "--out", out]
    with subprocess.Popen(
        [sys.executable, "-m", "cas_async", "sweep", str(SLOW), *map(str, args)],
        cwd=ROOT,
        env=_ENV,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        encoding="utf-8",
        start_new_session=True,  # a group of its own: "as-ctrl-c" signals every process in it
    ) as process:
        try:
            first = _first_line(process, RUN_LIMIT)  # a run finished: the workers are busy
            assert first.startswith("[1/40] strategy.name=time seed "), first
            workers = _workers(process.pid)
            assert len(workers) == 2
            sent = time.monotonic()
            if target == "group":
                os.killpg(process.pid, signal.SIGINT)
            else:
                process.send_signal(signal.SIGINT)
            stdout, stderr = process.communicate(timeout=STOP_LIMIT)
            took = time.monotonic() - sent
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL)  # whatever is left of it
    assert process.returncode == 130, first + stderr
    # It waits for no run: the 38 runs left would take a minute or more. (Not a tight
    # bound: the workers' ends take their time on a loaded machine.)
    assert took < STOP_LIMIT
    assert "Traceback" not in stderr
    assert "KeyboardInterrupt" not in stderr
    assert re.search(r"sweep: interrupted after \d+ of 40 runs", stderr), stderr
    deadline = time.monotonic() + STOP_LIMIT
    while not all(_gone(pid) for pid in workers):
        assert time.monotonic() < deadline, "a worker outlived the sweep"
        time.sleep(0.05)
    rows = read_csv(out)
    assert 1 <= len(rows) < 40
    assert {row["status"] for row in rows} == {"completed"}
    table = (out / "table.md").read_text("utf-8")
    assert f"{len(rows)} of 40 runs (interrupted)" in table
    assert stdout.startswith(table)
    assert json.loads((out / "summary.json").read_text("utf-8"))["interrupted"] is True
    assert not list(out.glob("*.png"))  # the box plots are left out
    assert not [path.name for path in out.iterdir() if path.name.startswith(".")]


@pytest.mark.slow
@pytest.mark.skipif(
    not Path(f"/proc/{os.getpid()}/task/{os.getpid()}/children").exists(), reason="reads /proc"
)
def test_a_killed_worker_s_run_is_run_again_and_the_sweep_completes(tmp_path: Path) -> None:
    out = tmp_path / "out"
    args = ["--seeds", "5", "--jobs", "2", "--no-plots", "--out", out]
    with start_cli("sweep", SLOW, *args) as process:
        try:
            first = _first_line(process, RUN_LIMIT)
            os.kill(_workers(process.pid)[0], signal.SIGKILL)  # as the OOM killer would
            _, stderr = process.communicate(timeout=RUN_LIMIT)
        finally:
            process.kill()
    assert process.returncode == 0, first + stderr
    rows = read_csv(out)
    assert [row["seed"] for row in rows] == [str(seed) for seed in range(1, 6)]
    assert {row["status"] for row in rows} == {"completed"}
    assert re.search(r"\(5 completed; 1 worker lost, [12] runs? sent again\)", stderr), stderr


@pytest.mark.slow
def test_a_run_whose_worker_dies_twice_is_failed_and_the_others_complete(tmp_path: Path) -> None:
    path = scenario(tmp_path)
    out = tmp_path / "out"
    finished = run_cli(
        "sweep", path, "--seeds", "1", "--vary", "trouble.mode=die,none", "--jobs", "2",
        "--no-plots", "--out", out,
    )  # fmt: skip
    assert finished.code == 1, finished.stderr
    assert [(row["trouble.mode"], row["status"], row["error"]) for row in read_csv(out)] == [
        ("die", "failed", "its worker process died 2 times while running it "
         "(the last time it exited with code 3)"),
        ("none", "completed", ""),  # in flight beside it: run again, not counted
    ]  # fmt: skip
    assert "(1 completed, 1 failed; 2 workers lost, " in finished.stderr.splitlines()[-1]


# -- in process: the Python API ------------------------------------------------------------


@pytest.mark.slow
def test_sweep_from_python_returns_the_outcome_and_writes_when_asked(tmp_path: Path) -> None:
    outcome = sweep(
        SMALL,
        seeds=1,
        vary=["strategy.name=solo"],
        overrides=["mission.buckets=2"],
        jobs=1,
        out=tmp_path,
        plots=False,
    )
    assert outcome.all_completed
    assert not outcome.interrupted
    assert [(run.point, run.seed, run.status) for run in outcome.runs] == [
        (0, 1, RunStatus.COMPLETED)
    ]
    assert outcome.runs[0].scalars["delivered"] == 2.0
    assert sorted(path.name for path in tmp_path.iterdir()) == [
        "runs.csv",
        "summary.json",
        "sweep.json",
        "table.md",
    ]


def test_a_sweep_stopped_before_it_starts_runs_nothing() -> None:
    plan = plan_sweep(SMALL, seeds=3, overrides=["mission.buckets=2"])
    progress = io.StringIO()
    outcome = run_sweep(plan, jobs=2, progress_to=progress, stop=lambda: True)
    assert (outcome.runs, outcome.interrupted, outcome.all_completed) == ((), True, False)
    assert progress.getvalue().startswith("sweep: interrupted after 0 of 3 runs (0 completed)")


@pytest.mark.slow
def test_a_sweep_stopped_after_its_first_run_keeps_it() -> None:
    plan = plan_sweep(SMALL, seeds=20, overrides=["mission.buckets=3"])
    progress = io.StringIO()
    outcome = run_sweep(
        plan, jobs=2, progress_to=progress, stop=lambda: "[1/" in progress.getvalue()
    )
    assert outcome.interrupted
    assert 1 <= len(outcome.runs) < 20
    assert all(run.completed for run in outcome.runs)


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_in_process_a_signal_stops_the_sweep_and_main_returns_130(tmp_path: Path) -> None:
    from cas_async._cli._main import main

    class SignalOnFirstRun(io.StringIO):
        """stderr that sends this process SIGINT as the first run is reported."""

        def write(self, text: str) -> int:
            if text.startswith("[1/"):
                os.kill(os.getpid(), signal.SIGINT)
            return super().write(text)

    out = tmp_path / "out"
    stdout, stderr = io.StringIO(), SignalOnFirstRun()
    before = signal.getsignal(signal.SIGINT)
    code = main(
        ["sweep", str(SMALL), "--seeds", "20", "--jobs", "2", "--out", str(out)],
        stdout=stdout,
        stderr=stderr,
    )
    assert code == 130, stderr.getvalue()
    assert signal.getsignal(signal.SIGINT) is before
    assert 1 <= len(read_csv(out)) < 20
    done = len(read_csv(out))
    assert (
        f"interrupted: {done} of 20 runs done ({out / 'runs.csv'}), the others and the box "
        f"plots left out; the same command with --resume runs the other {20 - done}"
    ) in stderr.getvalue()
    assert stdout.getvalue().startswith((out / "table.md").read_text("utf-8"))


@pytest.mark.parametrize("jobs", [0, -1])
def test_jobs_must_be_at_least_one(jobs: int) -> None:
    plan = plan_sweep(SMALL, seeds=1)
    with pytest.raises(ValueError, match="jobs must be at least 1"):
        run_sweep(plan, jobs=jobs)


# -- in process: --vary ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "key", "values", "labels"),
    [
        ("strategy.name=time,solo", "strategy.name", ("time", "solo"), ("time", "solo")),
        ("a.b=0.1, 0.5", "a.b", (0.1, 0.5), ("0.1", "0.5")),
        ("a.b=1,2.0", "a.b", (1, 2.0), ("1", "2.0")),
        ("a.b=true,false", "a.b", (True, False), ("true", "false")),
        ("a.b=[1, 2],[3,4]", "a.b", ([1, 2], [3, 4]), ("[1, 2]", "[3, 4]")),
        ('a.b="x,y",z', "a.b", ("x,y", "z"), ("x,y", "z")),
        ("a.b={c = 1, d = 2}", "a.b", ({"c": 1, "d": 2},), ("{c = 1, d = 2}",)),
        (" a . b =pkg.mod:Cls", "a.b", ("pkg.mod:Cls",), ("pkg.mod:Cls",)),
    ],
    ids=[
        "bare-text",
        "floats",
        "int-and-float",
        "bools",
        "arrays",
        "quoted-comma",
        "table",
        "import-path",
    ],
)
def test_vary_values_are_read_as_set_reads_them(
    text: str, key: str, values: tuple[Any, ...], labels: tuple[str, ...]
) -> None:
    axis = parse_vary(text)
    assert axis.key == key
    assert axis.values == values
    assert [type(value) for value in axis.values] == [type(value) for value in values]
    assert axis.labels == labels


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("strategy.name", "expected KEY=VALUE,VALUE,..."),
        ("=a,b", "expected KEY=VALUE,VALUE,..."),
        ("a..b=1", "expected KEY=VALUE,VALUE,..."),
        ("a.b=", "a.b: no values"),
        ("a.b=1,,2", "a.b: empty value"),
        ("a.b=1,", "a.b: empty value"),
        ("a.b=1,1", "a.b: value 1 is listed twice"),
        ('a.b=0.5,"0.5"', 'a.b: values 0.5 and "0.5" both read 0.5 in runs.csv: keep one'),
        ("run.seed=1,2", "run.seed is the sweep's own"),
    ],
    ids=[
        "no-equals",
        "no-key",
        "empty-key-part",
        "no-values",
        "empty-value",
        "trailing-comma",
        "value-twice",
        "same-label",
        "seed",
    ],
)
def test_a_wrong_vary_is_refused(text: str, says: str) -> None:
    with pytest.raises(ScenarioError, match=re.escape(says)) as caught:
        parse_vary(text)
    assert caught.value.problems[0][0] == "--vary"


def test_the_grid_is_the_product_of_the_axes_in_order() -> None:
    plan = plan_sweep(
        SMALL,
        seeds=2,
        vary=["strategy.name=time,solo", "transporters.speed=4,6.5"],
        overrides=["mission.buckets=3"],
    )
    assert plan.runs == 8
    assert [plan.describe(point) for point in range(len(plan.points))] == [
        "strategy.name=time transporters.speed=4",
        "strategy.name=time transporters.speed=6.5",
        "strategy.name=solo transporters.speed=4",
        "strategy.name=solo transporters.speed=6.5",
    ]
    assert plan.run_overrides(1, 2) == [
        *SWEEP_DEFAULTS,
        "mission.buckets=3",
        "strategy.name=time",
        "transporters.speed=6.5",
        "run.seed=2",
    ]
    assert not plan.real_time


def test_a_run_s_data_is_what_loading_it_gives() -> None:
    plan = plan_sweep(
        SMALL, seeds=2, vary=["strategy.name=time,solo"], overrides=["mission.buckets=3"]
    )
    for point, seed in [(0, 1), (1, 2)]:
        loaded = load_scenario(SMALL, plan.run_overrides(point, seed)).data
        assert plan.run_data(point, seed) == loaded
    assert "seed" not in plan.point_data(1)["run"]
    plan.run_data(0, 1)["mission"]["buckets"] = 99  # a copy: the plan is unchanged
    assert plan.run_data(0, 1)["mission"]["buckets"] == 3
    by_hand = SweepPlan(plan.path, 2, plan.axes, plan.overrides, plan.points)  # no contents
    assert by_hand.run_data(1, 2) == plan.run_data(1, 2)


def test_set_may_override_the_sweep_s_defaults() -> None:
    plan = plan_sweep(SMALL, seeds=1, overrides=["run.virtual=false", 'run.transport="udp"'])
    assert plan.real_time


def test_every_wrong_point_is_reported_once_per_problem() -> None:
    with pytest.raises(ScenarioError) as caught:
        plan_sweep(SMALL, seeds=1, vary=["transporters.speed=-1,2,-3,-4,-5,0"])
    error = caught.value
    assert error.file == str(SMALL)
    assert [key for key, _ in error.problems] == ["transporters.speed"] * 5
    assert error.problems[0][1].endswith("(at transporters.speed=-1)")


@pytest.mark.parametrize("seeds", [0, -3])
def test_seeds_must_be_at_least_one(seeds: int) -> None:
    with pytest.raises(ScenarioError, match="expected at least 1 seed"):
        plan_sweep(SMALL, seeds=seeds)


# -- in process: statistics, numbers, the table -------------------------------------------


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        ([], MetricStats(0)),
        ([3.0], MetricStats(1, 3.0, 0.0, 3.0, 3.0, 3.0)),
        ([4.0, 1.0, 3.0, 2.0], MetricStats(4, 2.5, statistics.stdev([1, 2, 3, 4]), 1.0, 2.5, 4.0)),
        ([1.0, math.nan, 3.0, math.inf], MetricStats(2, 2.0, math.sqrt(2), 1.0, 2.0, 3.0)),
    ],
    ids=["none", "one", "even-count", "not-finite-left-out"],
)
def test_summarise(values: list[float], expected: MetricStats) -> None:
    assert dataclasses.asdict(summarise(values)) == pytest.approx(dataclasses.asdict(expected))


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (28.14, "28.1"),
        (0.4123, "0.412"),
        (5.9, "5.90"),
        (0.99999, "1.00"),
        (9.996, "10.0"),
        (169.4, "169"),
        (1234.56, "1235"),
        (20.0, "20"),
        (0.0, "0"),
        (-3.456, "-3.46"),
        (1.2e-5, "1.20e-05"),
        (None, "n/a"),
        (math.nan, "nan"),
    ],
    ids=lambda value: str(value),
)
def test_numbers_have_three_significant_digits(value: float | None, text: str) -> None:
    assert format_number(value) == text


def _outcome(runs: list[SweepRun], *, interrupted: bool = False) -> SweepOutcome:
    plan = plan_sweep(SMALL, seeds=2, vary=["strategy.name=time,solo"])
    return SweepOutcome(plan, tuple(runs), 1.5, 2, interrupted)


def _run(
    point: int, seed: int, status: RunStatus = RunStatus.COMPLETED, **scalars: float
) -> SweepRun:
    return SweepRun(point, seed, status, None if status is RunStatus.COMPLETED else "boom", scalars)


def test_the_table_is_one_markdown_table_with_a_row_per_metric_and_point() -> None:
    outcome = _outcome(
        [
            _run(0, 1, makespan=28.14, line=0.5),
            _run(0, 2, makespan=30.0, line=0.25),
            _run(1, 1, makespan=12.0),
            _run(1, 2, RunStatus.FAILED, sim_time=3.0),
        ]
    )
    text = sweep_table(outcome)
    intro, blank, *table, blank2, left_out = text.splitlines()
    assert intro.startswith(
        "Sweep of thesis_5_8_1.toml, seeds 1-2, 2 grid points: 4 runs, 3 completed, 1 failed."
    )
    assert (blank, blank2) == ("", "")
    assert left_out == "Not in the figures: strategy.name=solo seed 2 (failed)."
    assert len({len(line) for line in table}) == 1  # aligned, also as plain text
    assert all(line.startswith("| ") and line.endswith(" |") for line in table)
    cells = [[cell.strip() for cell in line.strip("|").split("|")] for line in table]
    assert cells[0] == ["strategy.name", "metric", "runs", *FIGURES]
    assert all(rule.strip("-") in ("", ":") for rule in cells[1])
    assert cells[1][2].endswith(":")  # numbers to the right
    assert cells[2:] == [
        ["time", "makespan", "2/2", "29.1", "1.32", "28.1", "29.1", "30"],
        ["solo", "makespan", "1/2", "12", "0", "12", "12", "12"],
        ["time", "line", "2/2", "0.375", "0.177", "0.250", "0.375", "0.500"],
        ["solo", "line", "0/2", "n/a", "n/a", "n/a", "n/a", "n/a"],
        ["time", "sim_time", "0/2", "n/a", "n/a", "n/a", "n/a", "n/a"],
        ["solo", "sim_time", "0/2", "n/a", "n/a", "n/a", "n/a", "n/a"],
    ]


def test_an_interrupted_sweep_says_how_far_it_got() -> None:
    text = sweep_table(_outcome([_run(0, 1, makespan=3.0)], interrupted=True))
    assert ": 1 of 4 runs (interrupted), all completed." in text.splitlines()[0]


def test_a_pipe_in_a_value_does_not_break_the_table() -> None:
    plan = plan_sweep(SMALL, seeds=1)
    plan = SweepPlan(plan.path, 1, (parse_vary("strategy.name=a|b"),), (), ((0,),))
    text = sweep_table(SweepOutcome(plan, (_run(0, 1, makespan=1.0),), 0.1, 1))
    assert "| a\\|b " in text
