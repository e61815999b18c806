"""Stopping: how long ``python -m cas_async run`` takes to exit after SIGINT or SIGTERM.

Not part of ``python -m benchmarks`` (each point starts a process)::

    python -m benchmarks.stop [--scenarios thesis_5_8_1,scale_2500] [--runs 3]
                              [--signal SIGINT] [--at imports,0.5,1,2,4,8]

For each scenario and each moment, a fresh ``python -m cas_async run SCENARIO
--no-plots`` gets the signal, and the wall time from sending it to the process's
exit is measured. A moment is a number of wall seconds after the start, or
``imports``: as soon as the process handles SIGTERM (``SigCgt`` in
``/proc/<pid>/status``), that is while cas_async and its dependencies are being
imported. The scale scenarios build their robots for seconds, so the moments
cover importing, building, starting and running.

Figures per scenario and moment (median and maximum of ``--runs``): seconds to
exit; the exit codes seen; whether ``results.json`` was written and its status.
A run that ended before its signal is left out (the row says so when all did).

Target (exit status 1 when it fails): every run exits with 130 within
``LIMIT`` (1.0) seconds of the signal, without a traceback.
"""

from __future__ import annotations

import argparse
import json
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Final

from ._table import print_aligned

ROOT: Final = Path(__file__).resolve().parent.parent
SCENARIOS: Final = ROOT / "apps" / "fire_brigade" / "scenarios"
LIMIT: Final = 1.0  # wall seconds from the signal to the exit
DEADLINE: Final = 120.0  # a process still alive this long after the signal is killed
EXIT_INTERRUPTED: Final = 130


def _handles_sigterm(pid: int) -> bool:
    status = Path(f"/proc/{pid}/status").read_text(encoding="ascii")
    for line in status.splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    return False


def stop_once(scenario: Path, at: str, signum: signal.Signals) -> dict[str, Any]:
    """Starts a run, signals it at ``at``, and measures how it ended."""
    with tempfile.TemporaryDirectory() as out:
        started = time.perf_counter()
        process = subprocess.Popen(
            [sys.executable, "-m", "cas_async", "run", str(scenario), "--no-plots", "--out", out],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            if at == "imports":
                while not _handles_sigterm(process.pid) and process.poll() is None:
                    time.sleep(0.0005)
            else:
                time.sleep(max(0.0, float(at) - (time.perf_counter() - started)))
            sent = time.perf_counter()
            ended_first = process.poll() is not None
            process.send_signal(signum)
            _, stderr = process.communicate(timeout=DEADLINE)
            took = time.perf_counter() - sent
        finally:
            process.kill()
        results = Path(out) / "results.json"
        status = json.loads(results.read_text())["status"] if results.exists() else None
    return {
        "ended_first": ended_first,
        "seconds": took,
        "at_wall": sent - started,
        "exit": process.returncode,
        "results": status,
        "traceback": "Traceback" in stderr,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.stop", description=__doc__)
    parser.add_argument("--scenarios", default="thesis_5_8_1,scale_2500")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--signal", default="SIGINT", choices=("SIGINT", "SIGTERM"))
    parser.add_argument("--at", default="imports,0.3,0.5,1,2,4,8")
    args = parser.parse_args(argv)
    signum = signal.Signals[args.signal]
    rows = [("scenario", "at", "median s", "max s", "exits", "results.json", "pass")]
    failed = False
    for name in args.scenarios.split(","):
        for at in args.at.split(","):
            done = [stop_once(SCENARIOS / f"{name}.toml", at, signum) for _ in range(args.runs)]
            print(json.dumps({"scenario": name, "at": at, "runs": done}), file=sys.stderr)
            runs = [run for run in done if not run["ended_first"]]
            if not runs:
                rows.append((name, at, "-", "-", "-", "ended before the signal", "n/a"))
                continue
            seconds = [run["seconds"] for run in runs]
            ok = all(
                run["exit"] == EXIT_INTERRUPTED and run["seconds"] < LIMIT and not run["traceback"]
                for run in runs
            )
            failed |= not ok
            exits = ",".join(sorted({str(run["exit"]) for run in runs}))
            written = ",".join(sorted({str(run["results"] or "-") for run in runs}))
            rows.append(
                (
                    name,
                    at,
                    f"{statistics.median(seconds):.3f}",
                    f"{max(seconds):.3f}",
                    exits,
                    written,
                    "yes" if ok else "NO",
                )
            )
    print(f"signal: {args.signal}; target: exit 130 within {LIMIT} s, no traceback")
    print_aligned(rows, left=(0, 1, 4, 5))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
