"""How ``python -m cas_async run`` ends: failing on drops, and output into a closed pipe.

Real subprocesses, as a user runs them (see ``tests/test_cli.py``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

import pytest

from tests.test_cli import FAST, RUN_LIMIT, SHIPPED, read_results, run_cli, start_cli

pytestmark = pytest.mark.slow  # runs of the command line in subprocesses

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


def _into_head(out: Path, *extra: str) -> tuple[int, str]:
    """``python -m cas_async run ... | head -3``: the reader takes three lines and goes.

    Returns the exit code and stderr.
    """
    with start_cli("run", SHIPPED, *FAST, "--out", out, *extra) as process:
        assert process.stdout is not None
        assert process.stderr is not None
        try:
            lines = [process.stdout.readline() for _ in range(3)]
            assert lines[0].startswith("Fire Brigade"), lines
            process.stdout.close()  # as head does when it has its lines
            stderr = process.stderr.read()
            code = process.wait(timeout=RUN_LIMIT)
        finally:
            process.kill()
    return code, stderr


def test_a_reader_that_goes_away_ends_the_run_quietly_with_its_results(tmp_path: Path) -> None:
    out = tmp_path / "out"
    code, stderr = _into_head(out)
    assert code == 0, stderr
    assert "Traceback" not in stderr
    assert "BrokenPipeError" not in stderr
    assert read_results(out)["status"] == "completed"
    assert (out / "trace.csv").is_file()
    assert (out / "over_time.png").is_file()  # the figures come after the summary


def test_a_reader_that_goes_away_from_a_run_across_processes(tmp_path: Path) -> None:
    pytest.importorskip("zenoh", reason="runs across processes need the zenoh extra")
    out = tmp_path / "out"
    code, stderr = _into_head(out, "--processes", "2", "--no-plots")
    assert code == 0, stderr
    # Not "no traceback at all": on a loaded machine a worker may still log a barrier
    # message it handles after its Zenoh session closed (zenoh.ZError: session closed),
    # with or without a pipe; that is the workers' to fix, not the pipe's.
    assert "BrokenPipeError" not in stderr
    assert read_results(out)["status"] == "completed"
