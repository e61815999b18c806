"""The soak benchmark runs as documented and reports one well-formed JSON line.

A smoke test only: 20 robots for 1 second, as a user runs it (a real subprocess).
The figures themselves are not judged here; only their shape and consistency.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

FIELDS = {
    "name": str,
    "loop": str,
    "robots": int,
    "seconds": float,
    "handled": int,
    "handled_per_s": float,
    "dropped": dict,
    "rss_start_mib": float,
    "rss_end_mib": float,
    "rss_growth": float,
    "ok": bool,
}


@pytest.mark.slow
def test_a_short_soak_prints_one_json_line() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "benchmarks.soak", "--robots", "20", "--seconds", "1"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    json_lines = [line for line in result.stdout.splitlines() if line.startswith("{")]
    assert len(json_lines) == 1, f"stdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    row = json.loads(json_lines[0])
    for name, kind in FIELDS.items():
        assert isinstance(row.get(name), kind), f"{name}: {row.get(name)!r} is not a {kind}"
    assert row["name"] == "soak"
    assert row["robots"] == 20
    assert row["handled"] > 0
    assert all(isinstance(n, int) and n > 0 for n in row["dropped"].values())
    assert row["ok"] == (row["rss_growth"] < 0.10)
    assert row["sockets_open"] == 20
    assert row["sockets_left_open"] == 0
    # The exit status follows the verdict: 0 passed, 1 memory grew too much.
    assert result.returncode == (0 if row["ok"] else 1), result.stderr
