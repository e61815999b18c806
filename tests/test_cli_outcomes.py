"""How ``python -m cas_async run`` ends: failing on drops, and output into a closed pipe.

Real subprocesses, as a user runs them (see ``tests/test_cli.py``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

from tests.test_cli import FAST, SHIPPED, read_results, run_cli

DUPLICATES: Final = ("--set", "faults.duplicate=0.3")
"""A wire that delivers some datagrams twice: robots drop the copies (``duplicate``)."""


def test_drops_for_any_reason_fail_the_run_with_exit_1(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli(
        "run", SHIPPED, *FAST, *DUPLICATES, "--no-plots", "--out", out, "--fail-on-drops"
    )
    assert finished.code == 1, finished.stderr
    assert "FAILED" in finished.stdout.splitlines()[0]
    assert "dropped for any reason (--fail-on-drops): duplicate" in finished.stdout
    results = read_results(out)
    assert results["status"] == "failed"
    assert results["fail_on_drops"] == []
    assert results["failing_drops"]["duplicate"] > 0
    assert results["failing_drops"] == results["protocol_errors"]
    assert results["delivered"] == results["target"]  # the mission itself was done


def test_drops_for_other_reasons_leave_a_completed_run_completed(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli(
        "run", SHIPPED, *FAST, *DUPLICATES, "--no-plots", "--out", out,
        "--fail-on-drops", "decode,queue_full",
    )  # fmt: skip
    assert finished.code == 0, finished.stderr
    assert "(none dropped: passed)" in finished.stdout
    results = read_results(out)
    assert results["status"] == "completed"
    assert results["fail_on_drops"] == ["decode", "queue_full"]
    assert results["failing_drops"] == {}
    assert results["protocol_errors"]["duplicate"] > 0


def test_a_reason_that_is_no_reason_is_a_usage_error(tmp_path: Path) -> None:
    finished = run_cli("run", SHIPPED, *FAST, "--fail-on-drops", "Queue-Full")
    assert finished.code == 2
    assert "expected drop reasons such as decode.wrong_type or queue_full" in finished.stderr
