"""Parallel: a simulation split across processes against the same run in one process.

Not part of ``python -m benchmarks`` (``scale_10000`` takes minutes)::

    python -m benchmarks.parallel [--scenarios scale_2500,scale_10000] [--processes 2]
                                  [--seed 1] [--latency L] [--runs 1]

Each scenario (``apps/fire_brigade/scenarios/<name>.toml``, virtual time) runs with
``python -m cas_async run --virtual`` in one process, then with ``--processes N``
for each N given, in fresh processes, one after the other. Figures per run:

* wall seconds of the whole command (start-up, building every robot, the run,
  writing the results) and the CPU seconds of it and its workers;
* the speed-up: the one-process wall time over this one, and the CPU efficiency: the
  one-process CPU seconds over this run's (1: splitting the run cost no CPU);
* windows (the synchronizations of the lookahead model, see
  ``cas_async/scenario/_processes/_windows.py``) and windows per simulated second;
* cross-process effects (datagrams and hand-over steps from a robot of one worker
  to a robot of another) per wall second;
* the longest time a worker waited for the others and for grants (wall seconds, and
  its share of the run's wall time), and of that for grants alone (with every other
  window in: the world was on its way);
* with an interaction range, the workers each worker depended on, per window (mean);
* the world's wall seconds observing windows (its mirror, objective, trace, samples);
* the load imbalance: the busiest worker's busy time over the average worker's
  (1 is balanced);
* whether the results are identical to the one-process run's: ``trace.csv`` byte
  for byte, and ``results.json`` but for the figures of the distribution itself
  (workers, their wait, the cross-process effects) and the wall times.

Targets (exit status 1 when one fails, or a run does not complete, or results
differ): ``scale_2500`` with 2 processes at least ``SPEEDUP_TARGET`` (1.4) times
faster than one process, using at most ``CPU_TARGET`` (1.2) times its CPU (issue 45;
on the project's 2-core machine).

One table, and one JSON line per run on stdout; progress on stderr.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final

from ._table import print_aligned

ROOT: Final = Path(__file__).resolve().parent.parent
SCENARIOS: Final = ROOT / "apps" / "fire_brigade" / "scenarios"
SPEEDUP_TARGET: Final = 1.4
CPU_TARGET: Final = 1.2
TARGET_CASE: Final = ("scale_2500", 2)
DISTRIBUTION_KEYS: Final = frozenset({
    "workers", "worker_waited_s", "worker_waited_grant_s", "world_observing_s",
    "cross_process_effects", "window_busy_mean_s", "window_busy_max_s", "windows",
    "dependency_set_mean", "watched_robots_mean",
})  # fmt: skip
"""``results.json`` ``extra`` figures that describe the distribution, not the run."""


def imbalance(extra: dict[str, Any]) -> float | None:
    """Over the run, the busiest worker's busy time over the average worker's (1: balanced).

    A worker waits for the workers it depends on: an imbalance among neighbours
    turns into waiting (see ``cas_async/scenario/_processes/_window_costs.py``).
    """
    mean, most = extra.get("window_busy_mean_s"), extra.get("window_busy_max_s")
    return round(most / mean, 2) if mean and most else None


def cpu_of_children() -> float:
    """User and system CPU seconds of the finished children (and theirs) so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_once(
    scenario: Path, processes: int, seed: int, latency: float | None, out: Path
) -> dict[str, Any]:
    """One ``python -m cas_async run``: what it measured and what it cost."""
    command = [
        sys.executable, "-m", "cas_async", "run", str(scenario), "--virtual", "--no-plots",
        "--seed", str(seed), "--out", str(out),
    ]  # fmt: skip
    if latency is not None:
        command += ["--set", f"network.latency={latency}"]
    if processes > 1:
        command += ["--processes", str(processes)]
    cpu, started = cpu_of_children(), time.perf_counter()
    finished = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
    wall, cpu = time.perf_counter() - started, cpu_of_children() - cpu
    if finished.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited {finished.returncode}:\n{finished.stderr}")
    results = json.loads((out / "results.json").read_text(encoding="utf-8"))
    return {"wall": wall, "cpu": cpu, "results": results, "trace": out / "trace.csv"}


def share(fraction: float | None) -> str:
    """A fraction as a percentage; ``-`` where there is none (one process)."""
    return "-" if fraction is None else f"{fraction:.0%}"


def comparable(results: dict[str, Any]) -> dict[str, Any]:
    """``results`` without wall times and the figures of the distribution itself."""
    kept = {k: v for k, v in results.items() if not k.startswith("wall_time")}
    kept["extra"] = {
        k: v for k, v in results.get("extra", {}).items() if k not in DISTRIBUTION_KEYS
    }
    return kept


def differences(one: dict[str, Any], other: dict[str, Any]) -> list[str]:
    """The keys whose values differ between two comparable results."""
    keys = sorted(set(one) | set(other))
    return [key for key in keys if one.get(key) != other.get(key)]


def measure(
    name: str, processes: Sequence[int], seed: int, latency: float | None, runs: int, work: Path
) -> list[dict[str, Any]]:
    """Every configuration of one scenario, ``runs`` times each (medians reported)."""
    scenario = SCENARIOS / f"{name}.toml"
    rows: list[dict[str, Any]] = []
    alone: dict[str, Any] | None = None
    for n in (1, *processes):
        walls, cpus, last = [], [], None
        for k in range(runs):
            print(f"{name}: {n} process{'es' if n > 1 else ''}, run {k + 1}...", file=sys.stderr)
            last = run_once(scenario, n, seed, latency, work / f"{name}-{n}-{k}")
            walls.append(last["wall"])
            cpus.append(last["cpu"])
        assert last is not None
        results = last["results"]
        extra = results.get("extra", {})
        sim = float(results.get("sim_time") or 0.0)
        wall = statistics.median(walls)
        row: dict[str, Any] = {
            "scenario": name,
            "processes": n,
            "status": results["status"],
            "wall_s": round(wall, 2),
            "cpu_s": round(statistics.median(cpus), 2),
            "sim_s": round(sim, 3),
            "windows": extra.get("windows"),
            "windows_per_sim_s": round(extra["windows"] / sim, 1) if extra.get("windows") else None,
            "effects_per_s": round(extra.get("cross_process_effects", 0) / wall, 1),
            "waited_s": extra.get("worker_waited_s"),
            "waited_share": round(extra["worker_waited_s"] / wall, 3)
            if extra.get("worker_waited_s") is not None
            else None,
            "dependency_set_mean": extra.get("dependency_set_mean"),
            "grant_s": extra.get("worker_waited_grant_s"),
            "observing_s": extra.get("world_observing_s"),
            "imbalance": imbalance(extra),
        }
        if alone is None:
            alone = last
            row["speedup"] = 1.0
            row["cpu_efficiency"] = 1.0
            row["identical"] = True
        else:
            row["speedup"] = round(rows[0]["wall_s"] / wall, 2)
            row["cpu_efficiency"] = round(rows[0]["cpu_s"] / row["cpu_s"], 2)
            same_trace = alone["trace"].read_bytes() == last["trace"].read_bytes()
            differ = differences(comparable(alone["results"]), comparable(results))
            row["identical"] = same_trace and not differ
            if not row["identical"]:
                row["differs"] = (["trace.csv"] if not same_trace else []) + differ
        rows.append(row)
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.parallel", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--scenarios", default="scale_2500,scale_10000",
                        help="Fire Brigade scenarios, by file name without .toml")  # fmt: skip
    parser.add_argument("--processes", default="2",
                        help="worker process counts, comma-separated (default 2)")  # fmt: skip
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--latency", type=float, default=None,
                        help="network.latency (default: the scenario's)")  # fmt: skip
    parser.add_argument("--runs", type=int, default=1, help="runs per configuration (medians)")
    args = parser.parse_args(argv)
    counts = [int(n) for n in args.processes.split(",")]
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="cas_async-parallel-") as work:
        for name in args.scenarios.split(","):
            rows += measure(name, counts, args.seed, args.latency, args.runs, Path(work))
    header = ["scenario", "procs", "wall s", "cpu s", "speed-up", "cpu eff", "sim s",
              "windows", "win/sim s", "effects/s", "waited s", "waited", "grant s",
              "observing s", "busy max/mean", "deps", "identical"]  # fmt: skip
    table = [
        [str(value) for value in (
            r["scenario"], r["processes"], r["wall_s"], r["cpu_s"], r["speedup"],
            r["cpu_efficiency"], r["sim_s"], r["windows"], r["windows_per_sim_s"],
            r["effects_per_s"], r["waited_s"], share(r["waited_share"]), r["grant_s"],
            r["observing_s"], r["imbalance"], r["dependency_set_mean"],
        )] + ["yes" if r["identical"] else f"NO: {', '.join(r['differs'])}"]
        for r in rows
    ]  # fmt: skip
    print_aligned([header, *table], left={0, len(header) - 1})
    for row in rows:
        print(json.dumps({"bench": "parallel", **row}))
    failed = [r for r in rows if r["status"] != "completed" or not r["identical"]]
    target = [r for r in rows if (r["scenario"], r["processes"]) == TARGET_CASE]
    for row in target:
        fast = row["speedup"] >= SPEEDUP_TARGET
        lean = row["cpu_efficiency"] >= 1 / CPU_TARGET
        cpu = round(1 / row["cpu_efficiency"], 2)
        print(f"target: {TARGET_CASE[0]} with {TARGET_CASE[1]} processes at least "
              f"{SPEEDUP_TARGET}x faster than one: {row['speedup']}x, "
              f"{'met' if fast else 'NOT met'}; at most {CPU_TARGET}x its CPU: "
              f"{cpu}x, {'met' if lean else 'NOT met'}")  # fmt: skip
        if not (fast and lean):
            failed.append(row)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
