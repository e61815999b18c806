"""Nothing a sweep finished is lost: ``runs.csv`` as runs finish, ``sweep.json``, ``--resume``.

In process and fast: the runs are those of a toy app (``tests/scenario/sweep_apps.py``,
about 20 ms each) in a ``ThreadPoolExecutor``, which the Python API takes as it
takes any ``concurrent.futures.Executor``; the command line is ``main()``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from cas_async._cli._main import main
from cas_async.scenario import RunStatus, ScenarioError
from cas_async.scenario.sweeps import SweepPlan, SweepRun, plan_sweep, run_sweep
from cas_async.scenario.sweeps._manifest import check_resume, write_manifest
from cas_async.scenario.sweeps._runs_file import RunsFile, read_runs, write_runs_csv
from tests.scenario.sweep_apps import scenario

MODES = "trouble.mode=none,sleep"


@pytest.fixture
def threads() -> Iterator[ThreadPoolExecutor]:
    with ThreadPoolExecutor(2) as executor:
        yield executor


def rows(out: Path) -> list[dict[str, str]]:
    with (out / "runs.csv").open(encoding="utf-8", newline="") as stream:
        return list(csv.DictReader(stream))


def keys(found: list[dict[str, str]]) -> list[tuple[str, str]]:
    return [(row["trouble.mode"], row["seed"]) for row in found]


def small_plan(folder: Path, *lines: str, seeds: int = 3, vary: str = MODES) -> SweepPlan:
    return plan_sweep(scenario(folder, *lines), seeds=seeds, vary=[vary])


# -- runs.csv as the runs finish ---------------------------------------------------------------


def _run(point: int, seed: int, error: str | None = None, **scalars: float) -> SweepRun:
    status = RunStatus.FAILED if error else RunStatus.COMPLETED
    return SweepRun(point, seed, status, error, scalars)


def test_each_finished_run_is_a_whole_row_at_once(tmp_path: Path) -> None:
    plan = small_plan(tmp_path)
    path = tmp_path / "runs.csv"
    runs_file = RunsFile(path, plan)
    assert path.read_text("utf-8") == "trouble.mode,seed,status,error\n"
    runs_file.add(_run(1, 2, "RuntimeError: no", wall_time=0.5))
    runs_file.add(_run(0, 1, makespan=2.25, wall_time=0.25))  # a new metric: a new header
    runs_file.add(_run(0, 3, wall_time=0.125))
    assert path.read_text("utf-8").splitlines() == [
        "trouble.mode,seed,status,error,wall_time,makespan",
        "sleep,2,failed,RuntimeError: no,0.5,",
        "none,1,completed,,0.25,2.25",
        "none,3,completed,,0.125,",
    ]
    runs_file.close()
    runs_file.close()  # idempotent


def test_rows_read_back_as_written_and_rewrite_to_the_same_bytes(tmp_path: Path) -> None:
    plan = small_plan(tmp_path)
    path = tmp_path / "runs.csv"
    runs = [
        _run(0, 1, makespan=2.2, wall_time=1 / 3, odd=math.nan),
        _run(0, 2, 'ValueError: "quoted", with a comma\nand a second line', wall_time=0.1),
        _run(1, 3, makespan=1e-300, big=math.inf),
    ]
    write_runs_csv(plan, runs, path)
    before = path.read_bytes()
    back = read_runs(path, plan)
    assert [(run.point, run.seed, run.status, run.error) for run in back] == [
        (run.point, run.seed, run.status, run.error) for run in runs
    ]
    assert back[0].scalars["wall_time"] == 1 / 3
    assert math.isnan(back[0].scalars["odd"])
    assert back[2].scalars == {"makespan": 1e-300, "big": math.inf}
    write_runs_csv(plan, back, path)
    assert path.read_bytes() == before


def test_a_torn_last_line_is_left_out_and_a_run_listed_twice_counts_once(tmp_path: Path) -> None:
    plan = small_plan(tmp_path)
    path = tmp_path / "runs.csv"
    write_runs_csv(plan, [_run(0, 1, wall_time=1.0), _run(0, 1, wall_time=2.0)], path)
    with path.open("a", encoding="utf-8") as stream:
        stream.write("none,2,compl")  # a crash in the middle of a row
    [run] = read_runs(path, plan)
    assert (run.point, run.seed, run.scalars) == (0, 1, {"wall_time": 1.0})


@pytest.mark.parametrize(
    ("text", "says"),
    [
        pytest.param("strategy,seed,status,error\n", "its columns do not start", id="columns"),
        pytest.param(
            "trouble.mode,seed,status,error\nraise,1,failed,\n", "raise is not a point", id="point"
        ),
        pytest.param("trouble.mode,seed,status,error\nnone,4,completed,\n", "seed '4'", id="seed"),
        pytest.param(
            "trouble.mode,seed,status,error\nnone,1,done,\n", "'done' is not", id="status"
        ),
        pytest.param("trouble.mode,seed,status,error\nnone,1\n", "expected 4 cells", id="cells"),
    ],
)
def test_a_runs_csv_of_another_sweep_is_refused(tmp_path: Path, text: str, says: str) -> None:
    plan = small_plan(tmp_path)
    (tmp_path / "runs.csv").write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError, match="--resume") as refused:
        read_runs(tmp_path / "runs.csv", plan)
    assert says in str(refused.value)


# -- sweep.json: the same sweep, or what changed -----------------------------------------------


@pytest.mark.parametrize(
    ("lines", "seeds", "vary", "says"),
    [
        pytest.param(
            ["[chores]", "target = 4", "per_robot = 2"],
            3,
            MODES,
            "the scenario changed (chores.per_robot = 2 added; chores.target = 4 added)",
            id="scenario",
        ),
        pytest.param([], 4, MODES, "the grid changed (--seeds was 3, now 4)", id="seeds"),
        pytest.param(
            [],
            3,
            "trouble.mode=none,sleep,raise",
            "the grid changed (--vary trouble.mode was none,sleep, now none,sleep,raise)",
            id="values",
        ),
        pytest.param(
            [],
            3,
            "chores.target=4,5",
            "the grid changed (--vary trouble.mode left out; --vary chores.target=4,5 added)",
            id="axis",
        ),
    ],
)
def test_resume_is_refused_saying_what_changed(
    tmp_path: Path, lines: list[str], seeds: int, vary: str, says: str
) -> None:
    write_manifest(tmp_path, small_plan(tmp_path))
    changed = small_plan(tmp_path, *lines, seeds=seeds, vary=vary)
    with pytest.raises(ScenarioError) as refused:
        check_resume(tmp_path, changed)
    assert str(refused.value) == f"--resume: {tmp_path}/ holds another sweep: {says}"


def test_what_does_not_change_the_runs_resumes(tmp_path: Path) -> None:
    plan = small_plan(tmp_path, "[chores]", "target = 4", "robots = 3")
    write_manifest(tmp_path, plan)
    moved = tmp_path / "elsewhere"
    moved.mkdir()
    text = scenario(moved, "# the same, otherwise written", "[chores]", "robots = 3  # as before")
    text.write_text(text.read_text("utf-8") + "target = 4\n", encoding="utf-8")
    assert check_resume(tmp_path, plan_sweep(text, seeds=3, vary=[MODES])) is None


def test_resume_needs_a_sweep_in_the_folder(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"nothing to resume in .*: no sweep\.json"):
        check_resume(tmp_path / "empty", small_plan(tmp_path))


def test_a_resumed_sweep_of_another_version_says_so(tmp_path: Path) -> None:
    plan = small_plan(tmp_path)
    manifest = write_manifest(tmp_path, plan)
    data = json.loads(manifest.read_text("utf-8"))
    manifest.write_text(json.dumps({**data, "cas_async": "0.0.1"}), encoding="utf-8")
    note = check_resume(tmp_path, plan)
    assert note is not None
    assert "was begun with cas_async 0.0.1" in note


# -- the loop: stop, resume, any executor --------------------------------------------------------


def test_a_stopped_sweep_resumed_runs_each_run_once(
    tmp_path: Path, threads: ThreadPoolExecutor
) -> None:
    plan = small_plan(tmp_path, "[trouble]", "seconds = 0.05")
    out = tmp_path / "out"
    progress = io.StringIO()
    first = run_sweep(
        plan,
        executor=threads,
        out=out,
        progress_to=progress,
        stop=lambda: "[2/" in progress.getvalue(),
    )
    assert first.interrupted
    before = rows(out)
    assert 2 <= len(before) < 6
    assert (out / "sweep.json").exists()
    progress = io.StringIO()
    second = run_sweep(plan, executor=threads, out=out, resume=True, progress_to=progress)
    lines = progress.getvalue().splitlines()
    assert lines[0] == f"resuming: {len(before)} of 6 runs done in {out}/, {6 - len(before)} to run"
    assert len([line for line in lines if line.startswith("[")]) == 6 - len(before)
    assert second.all_completed
    assert second.resumed == len(before)
    after = rows(out)
    assert keys(after) == [(mode, str(seed)) for mode in ("none", "sleep") for seed in (1, 2, 3)]
    assert [row for row in after if row in before] == before  # wall times too: not run again
    assert f"({6} completed; {len(before)} resumed)" in lines[-1]


def test_resuming_a_finished_sweep_runs_nothing(
    tmp_path: Path, threads: ThreadPoolExecutor
) -> None:
    plan = small_plan(tmp_path, seeds=1)
    out = tmp_path / "out"
    run_sweep(plan, executor=threads, out=out)
    before = (out / "runs.csv").read_bytes()
    progress = io.StringIO()
    outcome = run_sweep(plan, executor=threads, out=out, resume=True, progress_to=progress)
    assert (outcome.resumed, len(outcome.runs)) == (2, 2)
    assert (out / "runs.csv").read_bytes() == before
    assert progress.getvalue().endswith("wall, nothing left to run\n")


def test_runs_that_raise_or_exit_are_failed_rows_with_their_reason(
    tmp_path: Path, threads: ThreadPoolExecutor
) -> None:
    plan = small_plan(tmp_path, seeds=1, vary="trouble.mode=none,raise,exit")
    out = tmp_path / "out"
    outcome = run_sweep(plan, executor=threads, out=out)
    assert [(row["status"], row["error"]) for row in rows(out)] == [
        ("completed", ""),
        ("failed", "RuntimeError: the build broke on purpose"),
        ("failed", "the run exited: SystemExit: 3"),
    ]
    assert not outcome.interrupted
    summary = json.loads(json.dumps(outcome.runs[1].scalars))
    assert set(summary) == {"wall_time"}


class _Refusing(Executor):
    """Runs in a thread until ``after`` runs, then refuses, as a pool that broke."""

    def __init__(self, after: int) -> None:
        self._threads = ThreadPoolExecutor(1)
        self._left = after

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        if not self._left:
            raise RuntimeError("the pool is broken")
        self._left -= 1
        return self._threads.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._threads.shutdown(wait, cancel_futures=cancel_futures)


def test_an_executor_that_fails_ends_the_sweep_keeping_what_finished(tmp_path: Path) -> None:
    plan = small_plan(tmp_path)
    out = tmp_path / "out"
    executor = _Refusing(after=2)
    try:
        outcome = run_sweep(plan, executor=executor, jobs=1, out=out)
    finally:
        executor.shutdown()
    assert outcome.interrupted
    assert outcome.error == "the executor took no more runs: RuntimeError: the pool is broken"
    assert keys(rows(out)) == [("none", "1"), ("none", "2")]


def test_an_executor_must_be_one(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match=r"expected a concurrent\.futures\.Executor"):
        run_sweep(small_plan(tmp_path), executor=object())  # type: ignore[arg-type]


# -- the command line ------------------------------------------------------------------------


def _main(*args: str | Path) -> tuple[int, str, str]:
    stdout, stderr = io.StringIO(), io.StringIO()
    code = main([str(arg) for arg in args], stdout=stdout, stderr=stderr)
    return code, stdout.getvalue(), stderr.getvalue()


def test_resume_is_refused_after_the_scenario_changed(
    tmp_path: Path, threads: ThreadPoolExecutor
) -> None:
    path = scenario(tmp_path, "[chores]", "target = 5")
    out = tmp_path / "out"
    run_sweep(plan_sweep(path, seeds=2, vary=[MODES]), executor=threads, out=out)
    before = (out / "runs.csv").read_bytes()
    scenario(tmp_path, "[chores]", "target = 4")
    code, stdout, stderr = _main("sweep", path, "--seeds", "2", "--vary", MODES, "--out", out,
                                 "--resume")  # fmt: skip
    assert code == 2
    assert stderr == (
        f"error: --resume: {out}/ holds another sweep: the scenario changed "
        "(chores.target was 5, now 4)\n"
    )
    assert stdout == ""
    assert (out / "runs.csv").read_bytes() == before


def test_resume_with_nothing_to_resume_makes_no_folder(tmp_path: Path) -> None:
    out = tmp_path / "out"
    code, _, stderr = _main("sweep", scenario(tmp_path), "--seeds", "1", "--out", out, "--resume")
    assert code == 2
    assert stderr.startswith(f"error: --resume: nothing to resume in {out}/")
    assert not out.exists()


def test_cluster_and_jobs_are_one_or_the_other(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exited:
        _main("sweep", scenario(tmp_path), "--seeds", "1", "--jobs", "2", "--cluster", "tcp://x:1")
    assert exited.value.code == 2
    assert "--cluster: not allowed with argument --jobs" in capsys.readouterr().err


def test_cluster_needs_the_dask_extra(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    out = tmp_path / "out"
    code, _, stderr = _main("sweep", scenario(tmp_path), "--seeds", "1", "--cluster", "tcp://x:1",
                            "--out", out)  # fmt: skip
    assert code == 2
    assert stderr == (
        "error: --cluster needs the dask extra (distributed): pip install 'cas_async[dask]'\n"
    )
