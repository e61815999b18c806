"""The learning-environment benchmark runs as documented and reports well-formed JSON lines.

A smoke test only: a few robots, a few steps, one run, as a user runs it (a real
subprocess). Speeds are not judged (the machine is shared); the profile's split
must cover the whole time, and the env's own code must show in it.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("pettingzoo")

ROOT = Path(__file__).resolve().parent.parent.parent

FIELDS = {
    "name": str,
    "env": str,
    "robots": int,
    "steps": int,
    "runs": int,
    "dt": float,
    "reset_s": float,
    "first_step_s": float,
    "steps_per_s": float,
    "steps_per_s_runs": list,
    "share": dict,
}


def test_a_short_benchmark_run_prints_a_table_and_one_json_line_per_case() -> None:
    command = [
        sys.executable, "-m", "benchmarks.rl", "--robots", "4,25", "--steps", "3", "--runs", "1",
    ]  # fmt: skip
    result = subprocess.run(
        command, cwd=ROOT, capture_output=True, text=True, timeout=120, check=False
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    rows = [json.loads(line) for line in lines if line.startswith("{")]
    assert [(row["env"], row["robots"]) for row in rows] == [
        ("gathering", 4),
        ("gathering", 25),
        ("fire_brigade", 8),  # 4 Transporters in one cell, its 2 Generators and 2 Sinks
        ("fire_brigade", 29),
    ]
    for row in rows:
        for name, kind in FIELDS.items():
            assert isinstance(row.get(name), kind), f"{name}: {row.get(name)!r} is not a {kind}"
        assert row["steps_per_s"] > 0
        share = row["share"]
        assert set(share) == {"runtime", "env", "app", "callbacks", "driver", "other"}
        assert sum(share.values()) == pytest.approx(1.0, abs=0.01)
        assert share["runtime"] > 0.2
        assert share["env"] > 0
        assert share["app"] > 0
        assert share["callbacks"] > 0
    assert lines[0].split()[:3] == ["env", "robots", "reset"]
