"""Runs with an interaction range across processes: each worker watches only what can reach its own.

``ranged/crossing``: a row of beacons, and a runner far faster than anything else
driving from one end of the world to the other and back, looking around and
calling out as it goes. Split across workers by region, the runner crosses every
worker's strip: whom each worker watches, and depends on, changes all the time.
The results must not: byte-identical ``trace.csv`` and the same ``results.json``
(but for how the run was spread) in 1, 2, 3 and 4 processes, with datagrams lost
out of range counted alike; a query wider than the range fails the run naming it;
a worker killed mid-run is named with its robots.
"""

from __future__ import annotations

import json
import os
import re
import signal
import time
from pathlib import Path
from typing import Any, Final

import pytest

from tests.processes_support import processes, read_results, run_cli

pytest.importorskip("zenoh")
pytestmark = pytest.mark.slow

CROSSING: Final = Path(__file__).parent / "ranged" / "crossing.toml"
SPREAD: Final = frozenset({
    "workers", "worker_waited_s", "worker_waited_grant_s", "world_observing_s",
    "cross_process_effects", "window_busy_mean_s", "window_busy_max_s", "windows",
    "dependency_set_mean", "watched_robots_mean",
})  # fmt: skip
"""``extra`` figures that describe how a run was spread, not the run."""


def _results(out: Path) -> dict[str, Any]:
    data = read_results(out)
    data.pop("wall_time", None)
    data["extra"] = {k: v for k, v in data.get("extra", {}).items() if k not in SPREAD}
    return data


def _run(tmp: Path, name: str, *args: str) -> tuple[bytes, dict[str, Any], str]:
    out = tmp / name
    done = run_cli(tmp / f"logs-{name}", "run", CROSSING, "--no-plots", "--out", out, *args)
    assert done.code == 0, done.output
    return (out / "trace.csv").read_bytes(), _results(out), done.output


@pytest.mark.parametrize(
    "overrides",
    [
        pytest.param((), id="answers-at-once"),
        pytest.param(("--set", "line.answer_after=0.4"), id="answers-lost-out-of-range"),
    ],
)
def test_a_ranged_run_gives_the_same_results_in_1_2_3_and_4_processes(
    tmp_path: Path, overrides: tuple[str, ...]
) -> None:
    trace, results, _ = _run(tmp_path, "one", *overrides)
    if overrides:  # the runner is gone by the time a beacon answers: lost, counted
        assert results["protocol_errors"]["transport.out_of_range"] > 0
    watched = []
    for workers in (2, 3, 4):
        spread_trace, spread_results, output = _run(
            tmp_path, f"procs{workers}", *overrides, "--processes", str(workers)
        )
        assert spread_trace == trace, f"{workers} processes"
        assert spread_results == results, f"{workers} processes"
        extra = read_results(tmp_path / f"procs{workers}")["extra"]
        assert 1 <= extra["dependency_set_mean"] <= workers - 1
        watched.append(extra["watched_robots_mean"])
        assert "dependency set mean" in output
    assert max(watched) < 13  # a worker watches some of the others' robots, never all


def test_a_query_wider_than_the_range_fails_the_run_naming_it(tmp_path: Path) -> None:
    out = tmp_path / "out"
    done = run_cli(
        tmp_path / "logs", "run", CROSSING, "--no-plots", "--processes", "2",
        "--set", "line.look=15", "--out", out,
    )  # fmt: skip
    assert done.code == 1, done.output
    error = read_results(out)["error"]
    assert "asked for the robots within 15; this run's interaction range is 10" in error


def test_a_worker_killed_mid_run_is_named_with_its_robots(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with processes(tmp_path / "logs") as started:
        process = started.start(
            "run", "run", CROSSING, "--no-plots", "--processes", "2", "--out", out,
            "--set", "line.legs=40", "--set", "run.max_time=600",
        )  # fmt: skip
        deadline = time.monotonic() + 60
        while len(process.children()) < 2 and time.monotonic() < deadline and process.running():
            time.sleep(0.05)
        while "t=" not in process.errors() and time.monotonic() < deadline:
            time.sleep(0.05)  # the run is under way
        children = process.children()
        assert len(children) == 2, process.output()
        os.kill(children[1], signal.SIGKILL)
        code = process.wait(60)
    assert code == 1, process.output()
    results = json.loads((out / "results.json").read_text())
    # which child joined first, and so is worker 0, is a race: the error names the pid killed
    assert re.search(rf"worker [01] is gone: its process {children[1]} ", results["error"])
    assert "robots are lost: " in results["error"]
