"""The timers benchmark runs as documented and reports well-formed JSON lines.

A smoke test only: 30 timers, one run, as a user runs it (a real subprocess).
Lateness figures are not judged (the machine is shared), except what no load can
change: the stdlib loop's timers never go off early.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from cas_async import uvloop_available

ROOT = Path(__file__).resolve().parent.parent

FIELDS = {
    "name": str,
    "loop": str,
    "timers": int,
    "runs": int,
    "median_us": float,
    "p90_us": float,
    "max_us": float,
    "early": float,
}


def test_a_short_timers_run_prints_a_table_and_one_json_line_per_loop() -> None:
    command = [sys.executable, "-m", "benchmarks.timers", "--timers", "30", "--runs", "1"]
    result = subprocess.run(
        command, cwd=ROOT, capture_output=True, text=True, timeout=60, check=False
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    rows = [json.loads(line) for line in lines if line.startswith("{")]
    loops = ["stdlib epoll (stock)", "stdlib (loop_factory)"]
    loops += ["uvloop"] if uvloop_available() else []
    assert [row["loop"] for row in rows] == loops, f"stdout:\n{result.stdout}"
    for row in rows:
        for name, kind in FIELDS.items():
            assert isinstance(row.get(name), kind), f"{name}: {row.get(name)!r} is not a {kind}"
        assert (row["name"], row["timers"], row["runs"]) == ("timer_lateness", 30, 1)
        assert row["median_us"] <= row["p90_us"] <= row["max_us"]
        if row["loop"].startswith("stdlib"):
            assert row["early"] == 0.0
            assert row["median_us"] >= 0
    # The table: header, rule, one line per loop, before the JSON lines.
    assert lines[0].split()[:3] == ["loop", "median", "us"]
    assert set(lines[1]) == {"-", " "}
    for line, loop in zip(lines[2:], loops, strict=False):
        assert line.startswith(loop), f"stdout:\n{result.stdout}"
