"""The scale benchmark runs as documented and reports well-formed JSON lines.

A smoke test only: the smallest count, once, as a user runs it (a real subprocess,
whose runs are subprocesses too). The figures themselves are not judged here.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

FIELDS = {
    "name": str,
    "scenario": str,
    "transporters": int,
    "robots": int,
    "runs": int,
    "wall_s": float,
    "sim_s": float,
    "wall_per_sim_s": float,
    "messages": int,
    "messages_per_wall_s": float,
    "peak_rss_mib": float,
    "rss_per_robot_kib": float,
    "wall_per_robot_sim_s_us": float,
    "completed": bool,
    "passed": bool,
}


def test_the_smallest_count_prints_one_json_line() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "benchmarks.scale", "--counts", "25", "--runs", "1", "--no-thesis"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    lines = [line for line in result.stdout.splitlines() if line.startswith("{")]
    assert len(lines) == 1, f"stdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    row = json.loads(lines[0])
    for name, kind in FIELDS.items():
        assert isinstance(row.get(name), kind), f"{name}: {row.get(name)!r} is not a {kind}"
    assert (row["name"], row["scenario"], row["transporters"]) == ("scale", "scale_25.toml", 25)
    assert row["robots"] == 29  # 25 Transporters, 2 Generators, 2 Sinks
    assert row["growth"] is None  # no smaller count to grow from
    assert row["completed"]
    assert result.returncode == (0 if row["passed"] else 1)


def test_an_unknown_count_is_refused() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "benchmarks.scale", "--counts", "30"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 2
    assert "no scale scenario for [30]" in result.stderr
