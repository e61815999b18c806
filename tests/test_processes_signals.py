"""A signal stops a run across processes at once, and its results say what it did until then.

``run --processes 2`` on virtual and on scaled time, interrupted once the run is
under way: SIGINT (Ctrl-C) or SIGTERM. The run exits with 130 (the CLI's code for
either) within a few seconds, no worker outlives it, and ``results.json`` says
``interrupted`` with the messages the workers' robots sent until then.
"""

from __future__ import annotations

import signal
import time
from pathlib import Path
from typing import Final

import pytest

from tests.processes_support import (
    SCENARIO,
    processes,
    read_results,
    wait_for_progress,
)

pytestmark = pytest.mark.slow  # a world and two workers per case

pytest.importorskip("zenoh")

STOP_LIMIT: Final = 10.0
"""Wall seconds from the signal to the exit (about 1 s; a loaded machine is slow)."""
GROUP_LIMIT: Final = 1.5
"""Wall seconds the run's workers may outlive it (killed: a few ms)."""
EXIT_CODES: Final = {signal.SIGINT: 130, signal.SIGTERM: 130}
TIMING: Final = {
    "virtual": ("--virtual", "--set", "mission.buckets=2000", "--set", "run.max_time=100000"),
    "scaled": ("--set", "run.time_factor=5", "--set", "mission.buckets=2000"),
}
"""Runs far too long to end by themselves before the signal."""


@pytest.mark.timeout(120)
@pytest.mark.parametrize("timing", sorted(TIMING))
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_stops_a_run_across_processes_with_its_counts(
    tmp_path: Path, timing: str, signum: signal.Signals
) -> None:
    out = tmp_path / "out"
    with processes(tmp_path / "logs") as started:
        run = started.start("run", "run", SCENARIO, *TIMING[timing], "--processes", "2",
                            "--out", out, "--no-plots")  # fmt: skip
        wait_for_progress(run, after=5.0)
        began = time.monotonic()
        run.popen.send_signal(signum)
        code = run.wait(STOP_LIMIT)
        stopped_in = time.monotonic() - began
        assert code == EXIT_CODES[signum], (code, run.output())
        assert stopped_in < STOP_LIMIT
        # The workers it started are told to stop and killed: none outlives it by more than a
        # moment (they would stop by themselves within about 2 s otherwise).
        deadline = time.monotonic() + GROUP_LIMIT
        while run.group_alive() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not run.group_alive(), "a worker outlived the run"
    result = read_results(out)
    assert result["status"] == "interrupted"
    assert result["sim_time"] >= 5.0
    # What the workers' robots did until the signal: counted, not lost with them.
    assert sum(result["messages_external"].values()) > 0, result["messages_external"]
    assert sum(result["messages_internal"].values()) > 0, result["messages_internal"]
