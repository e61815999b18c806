"""The shipped §5.8.1 scenario as a user runs it: real UDP sockets, scaled real time.

Every robot has its own socket on 127.0.0.1, so hand-overs cross the operating
system's network stack.

The time factor is 100, not more: the run is no faster in wall time at 400 (the
work per message bounds it; simulated time only stretches), while the layers'
5 simulated second request timeouts shrink to 12.5 wall milliseconds, which a
loaded machine misses. At 100 the run takes about half a wall second.
"""

from __future__ import annotations

from pathlib import Path

from tests.test_cli import SCENARIOS, read_results, run_cli


def test_thesis_5_8_1_completes_over_udp(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli(
        "run",
        SCENARIOS / "thesis_5_8_1.toml",
        "--time-factor",
        "100",
        "--set",
        "mission.buckets=6",
        "--no-plots",
        "--out",
        out,
    )
    assert finished.code == 0, finished.stdout + finished.stderr
    results = read_results(out)
    assert results["config"]["run"]["transport"] == "udp"  # the file's default, kept
    assert results["config"]["run"]["virtual"] is False
    assert results["status"] == "completed"
    # On real time a bucket may still arrive while the swarm is being stopped.
    assert results["delivered"] >= results["target"] == 6
    assert results["statistics"]["messages"]["external"] > 0
    assert results["exchanges"] > 0
