"""``sweep --cluster``: a sweep on a Dask cluster (the ``dask`` extra), losing nothing.

A ``LocalCluster`` (a scheduler in this process, two worker processes, everything
on 127.0.0.1) is shared by the tests of this module; the command line runs as a
user runs it, a subprocess given ``--cluster`` its address. The documented
commands (``dask scheduler``, ``dask worker``) start a cluster of their own where
a test kills the scheduler. The runs are those of the Fire Brigade where results
are compared, else of a toy app (``tests/scenario/sweep_apps.py``) whose runs
sleep, raise or exit on demand.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Final

import pytest

from cas_async.scenario.sweeps import sweep
from tests.scenario.sweep_apps import scenario
from tests.test_cli import _ENV, ROOT, RUN_LIMIT, SCENARIOS, STOP_LIMIT, _first_line, run_cli

distributed = pytest.importorskip(
    "distributed", reason="the dask extra is not installed: pip install -e '.[dask]'"
)
dask = pytest.importorskip("dask")

pytestmark = pytest.mark.slow  # a cluster takes seconds to start; each test runs sweeps

SMALL: Final = SCENARIOS / "thesis_5_8_1.toml"
GRID: Final = ("--seeds", "2", "--vary", "strategy.name=time,solo", "--set", "mission.buckets=3")
START_LIMIT: Final = 60.0
"""Wall seconds a cluster may take to start (seconds, on a loaded machine)."""
LOOPBACK: Final = ("--host", "127.0.0.1", "--dashboard-address", "127.0.0.1:0")
"""A Dask node's addresses, its HTTP server's too (else on every interface, port 8787)."""


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[str, Any]]:
    """Two worker processes of one thread; a run whose workers die twice fails."""
    scratch = tmp_path_factory.mktemp("dask")
    with (
        dask.config.set(
            {
                "temporary-directory": str(scratch),  # else /tmp/dask-scratch-space stays
                "distributed.scheduler.allowed-failures": 1,
                # one run per worker at a time: none waits on a worker that dies
                "distributed.scheduler.worker-saturation": 1.0,
            }
        ),
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            # the scheduler's HTTP server runs anyway, by default on 8787: any free port
            # on loopback never clashes with another cluster of this machine
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
        ) as local,
        distributed.Client(local, set_as_default=False) as client,
    ):
        client.wait_for_workers(2, timeout=START_LIMIT)
        yield local.scheduler_address, client


def read_csv(out: Path) -> list[dict[str, str]]:
    with (out / "runs.csv").open(encoding="utf-8", newline="") as stream:
        return list(csv.DictReader(stream))


def progress_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("[")]


def start_sweep(*args: str | os.PathLike[str]) -> subprocess.Popen[str]:
    """``python -m cas_async sweep *args`` in a session of its own, as ``start_cli`` but for it."""
    return subprocess.Popen(
        [sys.executable, "-m", "cas_async", "sweep", *map(str, args)],
        cwd=ROOT,
        env=_ENV,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        encoding="utf-8",
        start_new_session=True,
    )


def test_the_cluster_writes_the_runs_csv_of_a_local_sweep(
    cluster: tuple[str, Any], tmp_path: Path
) -> None:
    address, _ = cluster
    here, there = tmp_path / "here", tmp_path / "there"
    local = run_cli("sweep", SMALL, *GRID, "--jobs", "2", "--no-plots", "--out", here)
    remote = run_cli("sweep", SMALL, *GRID, "--cluster", address, "--no-plots", "--out", there)
    assert (local.code, remote.code) == (0, 0), remote.stderr
    assert re.search(
        rf"\(4 completed\) in [\d.]+ s wall, 2 Dask workers at {address}$", remote.stderr
    )

    def but_wall_times(out: Path) -> list[dict[str, str]]:
        return [{k: v for k, v in row.items() if k != "wall_time"} for row in read_csv(out)]

    assert but_wall_times(here) == but_wall_times(there)
    assert list(read_csv(here)[0]) == list(read_csv(there)[0])  # the same columns, in order
    assert len(but_wall_times(there)) == 4


def test_a_worker_killed_mid_sweep_its_runs_go_to_the_other(
    cluster: tuple[str, Any], tmp_path: Path
) -> None:
    address, client = cluster
    path = scenario(tmp_path, "[trouble]", 'mode = "sleep"', "seconds = 0.4")
    out = tmp_path / "out"
    victim = sorted(client.run(os.getpid).values())[0]
    with start_sweep(
        path, "--seeds", "6", "--cluster", address, "--out", out, "--no-plots"
    ) as process:
        try:
            first = _first_line(process, RUN_LIMIT)
            os.kill(victim, signal.SIGKILL)  # as the OOM killer would; its nanny restarts it
            _, stderr = process.communicate(timeout=RUN_LIMIT)
        finally:
            process.kill()
    client.wait_for_workers(2, timeout=START_LIMIT)  # for the next test
    assert process.returncode == 0, first + stderr
    assert [row["seed"] for row in read_csv(out)] == [str(seed) for seed in range(1, 7)]
    assert {row["status"] for row in read_csv(out)} == {"completed"}
    assert re.search(r"\(6 completed; 1 worker lost, \d+ runs? sent again\)", stderr), stderr


def test_an_interrupted_sweep_resumed_runs_each_run_once(
    cluster: tuple[str, Any], tmp_path: Path
) -> None:
    address, _ = cluster
    path = scenario(tmp_path, "[trouble]", "seconds = 0.3")
    out = tmp_path / "out"
    args = ("--seeds", "3", "--vary", "trouble.mode=sleep,none", "--cluster", address)
    with start_sweep(path, *args, "--out", out) as process:
        try:
            seen = _first_line(process, RUN_LIMIT)
            while "[2/6]" not in seen:
                seen += _first_line(process, RUN_LIMIT)
            process.send_signal(signal.SIGINT)
            _, stderr = process.communicate(timeout=STOP_LIMIT)
        finally:
            process.kill()
    assert process.returncode == 130, seen + stderr
    before = read_csv(out)
    assert 2 <= len(before) < 6, seen + stderr
    assert f"the same command with --resume runs the other {6 - len(before)}" in stderr
    resumed = run_cli("sweep", path, *args, "--out", out, "--resume")
    assert resumed.code == 0, resumed.stderr
    assert resumed.stderr.startswith(f"resuming: {len(before)} of 6 runs done in {out}/")
    assert len(progress_lines(resumed.stderr)) == 6 - len(before)  # no run done twice
    after = read_csv(out)
    assert [(row["trouble.mode"], row["seed"]) for row in after] == [
        (mode, str(seed)) for mode in ("sleep", "none") for seed in (1, 2, 3)
    ]
    assert [row for row in after if row in before] == before  # wall times too
    summary = json.loads((out / "summary.json").read_text("utf-8"))
    assert (summary["completed"], summary["resumed"]) == (6, len(before))


def test_runs_that_raise_exit_or_kill_their_worker_are_failed_rows(
    cluster: tuple[str, Any], tmp_path: Path
) -> None:
    address, client = cluster
    path = scenario(tmp_path)
    out = tmp_path / "out"
    vary = "trouble.mode=none,raise,exit,die"
    finished = run_cli(
        "sweep", path, "--seeds", "1", "--vary", vary, "--cluster", address, "--out", out
    )
    client.wait_for_workers(2, timeout=START_LIMIT)  # the dead ones restarted
    assert finished.code == 1, finished.stderr
    assert [(row["trouble.mode"], row["status"], row["error"]) for row in read_csv(out)] == [
        ("none", "completed", ""),
        ("raise", "failed", "RuntimeError: the build broke on purpose"),
        ("exit", "failed", "the run exited: SystemExit: 3"),
        ("die", "failed", "its worker died 2 times while running it (killed, or out of memory?)"),
    ]
    summary = json.loads((out / "summary.json").read_text("utf-8"))
    assert (summary["completed"], summary["failed"]) == (1, 3)
    assert "sweep: 4 runs (1 completed, 3 failed; 2 workers lost, " in finished.stderr
    assert "Not in the figures: trouble.mode=raise seed 1 (failed)" in finished.stdout


def test_the_python_api_takes_the_client(cluster: tuple[str, Any], tmp_path: Path) -> None:
    _, client = cluster
    outcome = sweep(scenario(tmp_path), seeds=3, executor=client, out=tmp_path / "out", plots=False)
    assert outcome.all_completed
    assert outcome.ran_on.startswith("2 Dask workers at tcp://127.0.0.1:")
    assert len(read_csv(tmp_path / "out")) == 3
    assert not client.futures  # every result gathered and let go


# -- the documented commands: `dask scheduler`, `dask worker` -----------------------------------


@contextlib.contextmanager
def dask_commands(
    folder: Path, workers: int
) -> Iterator[tuple[str, list[subprocess.Popen[bytes]]]]:
    """``dask scheduler`` and ``dask worker`` processes, as the docs start them, on loopback."""
    command = str(Path(sys.executable).with_name("dask"))
    file = folder / "scheduler.json"
    env = {
        **os.environ,
        "PYTHONPATH": str(ROOT),  # the app, importable as the docs say it must be
        "DASK_TEMPORARY_DIRECTORY": str(folder),  # else /tmp/dask-scratch-space stays
    }
    processes: list[subprocess.Popen[bytes]] = []

    def start(*args: str) -> None:
        with (folder / f"dask-{len(processes)}.log").open("wb") as log:
            processes.append(
                subprocess.Popen(
                    [command, *args],
                    cwd=folder,
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=log,
                    stderr=log,
                    start_new_session=True,
                )
            )

    try:
        start("scheduler", "--port", "0", *LOOPBACK, "--scheduler-file", str(file))
        deadline = time.monotonic() + START_LIMIT
        address = None
        while address is None:
            assert time.monotonic() < deadline, "the scheduler did not start"
            with contextlib.suppress(FileNotFoundError, ValueError):  # not (wholly) written yet
                address = json.loads(file.read_text("utf-8"))["address"]
            time.sleep(0.05)
        start("worker", address, "--nworkers", str(workers), "--nthreads", "1", *LOOPBACK,
              "--local-directory", str(folder), "--death-timeout", "30")  # fmt: skip
        with distributed.Client(address, timeout=START_LIMIT, set_as_default=False) as client:
            client.wait_for_workers(workers, timeout=START_LIMIT)
        yield address, processes
    finally:
        for process in reversed(processes):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGTERM)
        for process in processes:
            try:
                process.wait(STOP_LIMIT)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait(STOP_LIMIT)


@pytest.mark.timeout(3 * START_LIMIT)  # a scheduler, two workers and two sweeps start
def test_on_the_documented_commands_a_lost_scheduler_ends_the_sweep_keeping_its_runs(
    tmp_path: Path,
) -> None:
    path = scenario(tmp_path, "[trouble]", 'mode = "sleep"', "seconds = 0.3")
    out = tmp_path / "out"
    with dask_commands(tmp_path, workers=2) as (address, (scheduler, _workers)):
        finished = run_cli("sweep", path, "--seeds", "2", "--cluster", address, "--out", out)
        assert finished.code == 0, finished.stderr
        with start_sweep(path, "--seeds", "20", "--cluster", address, "--out", out) as process:
            try:
                first = _first_line(process, RUN_LIMIT)
                os.killpg(scheduler.pid, signal.SIGKILL)
                _, stderr = process.communicate(timeout=RUN_LIMIT)
            finally:
                process.kill()
    assert process.returncode == 1, first + stderr
    done = len(read_csv(out))
    assert 1 <= done < 20
    lost = f"error: lost the connection to the Dask scheduler at {address}: {done} of 20 runs done"
    assert lost in stderr, stderr
    assert "Traceback" not in stderr
