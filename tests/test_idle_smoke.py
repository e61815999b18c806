"""The idle benchmark runs as documented and reports well-formed JSON lines.

A smoke test only: 20 robots for half a second, as a user runs it (a real
subprocess). The figures are not judged here; only their shape and consistency.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from cas_async import uvloop_available

ROOT = Path(__file__).resolve().parent.parent

FIELDS = {
    "name": str,
    "loop": str,
    "robots": int,
    "layers": int,
    "transport": str,
    "wall_s": float,
    "cpu_s": float,
    "user_s": float,
    "system_s": float,
    "cpu_share": float,
    "wakeups_per_s": float,
    "target": float,
    "ok": bool,
}


@pytest.mark.slow
def test_a_short_idle_run_prints_one_json_line_per_loop() -> None:
    transport = "udp"  # the default, and the one with a socket per robot
    command = [sys.executable, "-m", "benchmarks.idle", "--robots", "20", "--seconds", "0.5"]
    command += ["--settle", "0.1", "--loop", "both", "--transport", transport]
    result = subprocess.run(
        command, cwd=ROOT, capture_output=True, text=True, timeout=30, check=False
    )
    rows = [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]
    loops = ["stdlib", "uvloop"] if uvloop_available() else ["stdlib"]
    assert [row["loop"] for row in rows] == loops, f"stdout:\n{result.stdout}\n{result.stderr}"
    for row in rows:
        for name, kind in FIELDS.items():
            assert isinstance(row.get(name), kind), f"{name}: {row.get(name)!r} is not a {kind}"
        assert row["name"] == "idle"
        assert (row["robots"], row["layers"], row["transport"]) == (20, 5, transport)
        assert row["cpu_s"] >= 0
        assert row["ok"] == (row["cpu_share"] < row["target"])
    table = [line for line in result.stdout.splitlines() if line.startswith("idle ")]
    assert len(table) == len(rows)
    # The exit status follows the verdicts: 0 every loop passed, 1 one did not.
    assert result.returncode == (0 if all(row["ok"] for row in rows) else 1), result.stderr
