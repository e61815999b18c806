"""Sweep: the same sweep on a Dask cluster and in local worker processes, side by side.

Not part of ``python -m benchmarks`` (it takes minutes; it needs the ``dask`` extra)::

    python -m benchmarks.sweep [--seeds 20] [--reps 3] [--cluster ADDRESS]

The sweep is 40 runs of ``thesis_5_8_2`` (seeds 1-20 x ``strategy.name=time,solo``),
run by the command line as a user runs it, in turns, ``--reps`` times each:

* ``sweep --jobs 2``: the sweep's own two worker processes, started by each sweep;
* ``sweep --cluster ADDRESS``: a cluster of two worker processes of one thread each
  that is already running (as a lab's is): a ``LocalCluster`` started here on
  127.0.0.1 and warmed with one sweep, unless ``--cluster`` names one.

Figures per sweep: wall seconds of the command; the sum of its runs' own wall
seconds (``wall_time`` in ``runs.csv``: a run's time in its worker, without handing
it out and back); CPU seconds of the command and its worker processes, and on the
cluster also of the cluster's processes (scheduler, nannies, workers) meanwhile (not
known for a cluster named with ``--cluster``); and whether its ``runs.csv`` is the
first local sweep's but for ``wall_time``. Then, per way, the median and the
fastest, and the cluster's overhead over the local sweep.

Target (exit status 1 when it fails, or a sweep fails or differs): the cluster's
median wall time at most ``OVERHEAD_TARGET`` (1.10) times the local one's (issue 46).
On a shared machine wall times move by tens of per cent between identical sweeps:
compare the CPU seconds too, and run it where nothing else runs for the verdict.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, Final

from ._table import print_aligned

ROOT: Final = Path(__file__).resolve().parent.parent
SCENARIO: Final = ROOT / "apps" / "fire_brigade" / "scenarios" / "thesis_5_8_2.toml"
VARY: Final = "strategy.name=time,solo"
OVERHEAD_TARGET: Final = 1.10
LOCAL: Final = "local --jobs 2"
CLUSTER: Final = "dask, 2 workers"


def cpu_of_children() -> float:
    """User and system CPU seconds of the finished children (and theirs) so far."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


@contextlib.contextmanager
def local_cluster(work: Path) -> Iterator[tuple[str, Any]]:
    """A cluster of 2 worker processes of one thread, on 127.0.0.1; its address and our process."""
    import dask
    import distributed
    import psutil

    with (
        dask.config.set({"temporary-directory": str(work)}),
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
        ) as cluster,
        distributed.Client(cluster, set_as_default=False) as client,
    ):
        client.wait_for_workers(2, timeout=120)
        yield cluster.scheduler_address, psutil.Process()


def cpu_of_cluster(here: Any) -> float:
    """CPU seconds of this process (the scheduler's) and its living children (nannies, workers)."""
    total = 0.0
    for process in [here, *here.children(recursive=True)]:
        with contextlib.suppress(Exception):  # it just ended
            times = process.cpu_times()
            total += times.user + times.system
    return total


def sweep(args: Sequence[str], out: Path) -> tuple[float, float]:
    """One ``python -m cas_async sweep``: wall and CPU seconds of it and its workers."""
    command = [
        sys.executable, "-m", "cas_async", "sweep", str(SCENARIO), "--vary", VARY,
        "--no-plots", "--out", str(out), *args,
    ]  # fmt: skip
    cpu, started = cpu_of_children(), time.perf_counter()
    finished = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
    wall, cpu = time.perf_counter() - started, cpu_of_children() - cpu
    if finished.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} exited {finished.returncode}:\n{finished.stderr}")
    return wall, cpu


def read_runs(out: Path) -> tuple[list[dict[str, str]], float]:
    """``runs.csv`` but for ``wall_time``, and the sum of the runs' own wall seconds."""
    with (out / "runs.csv").open(encoding="utf-8", newline="") as stream:
        rows = list(csv.DictReader(stream))
    own = sum(float(row["wall_time"] or 0) for row in rows)
    return [{k: v for k, v in row.items() if k != "wall_time"} for row in rows], own


def measure(seeds: int, reps: int, address: str | None, work: Path) -> list[dict[str, Any]]:
    """Both ways, in turns; a row per sweep."""
    rows: list[dict[str, Any]] = []
    with contextlib.ExitStack() as stack:
        here = None
        if address is None:
            address, here = stack.enter_context(local_cluster(work / "dask"))
            print(f"cluster at {address}; warming it with one sweep...", file=sys.stderr)
            sweep(["--seeds", "1", "--cluster", address], work / "warm")
        reference = None
        for rep in range(1, reps + 1):
            for way in (LOCAL, CLUSTER):
                print(f"{way}, sweep {rep} of {reps}...", file=sys.stderr)
                out = work / f"{way.split()[0]}-{rep}"
                seeds_args = ["--seeds", str(seeds)]
                if way == LOCAL:
                    wall, cpu = sweep([*seeds_args, "--jobs", "2"], out)
                else:
                    before = cpu_of_cluster(here) if here is not None else 0.0
                    wall, cpu = sweep([*seeds_args, "--cluster", address], out)
                    cpu = cpu + cpu_of_cluster(here) - before if here is not None else cpu
                runs, own = read_runs(out)
                reference = reference or runs
                statuses = {row["status"] for row in runs}
                rows.append(
                    {
                        "way": way,
                        "rep": rep,
                        "runs": len(runs),
                        "wall_s": round(wall, 2),
                        "runs_wall_s": round(own, 2),
                        "cpu_s": round(cpu, 2) if way == LOCAL or here is not None else None,
                        "completed": statuses == {"completed"},
                        "identical": runs == reference,
                    }
                )
    return rows


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.sweep", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("--seeds", type=int, default=20, help="seeds per strategy (default 20)")
    parser.add_argument("--reps", type=int, default=3, help="sweeps each way (default 3)")
    parser.add_argument("--cluster", metavar="ADDRESS",
                        help="a running Dask scheduler of 2 one-thread workers "
                        "(default: a LocalCluster started here)")  # fmt: skip
    args = parser.parse_args(argv)
    try:
        import distributed  # noqa: F401
    except ImportError:
        print("the sweep benchmark needs the dask extra: pip install -e '.[dask]'", file=sys.stderr)
        return 2
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    with tempfile.TemporaryDirectory(prefix="cas_async-sweep-") as work:
        rows = measure(args.seeds, args.reps, args.cluster, Path(work))
    table = [
        [r["way"], str(r["rep"]), str(r["runs"]), f"{r['wall_s']:.2f}", f"{r['runs_wall_s']:.2f}",
         "n/a" if r["cpu_s"] is None else f"{r['cpu_s']:.2f}",
         "yes" if r["completed"] else "NO", "yes" if r["identical"] else "NO"]
        for r in rows
    ]  # fmt: skip
    header = ["way", "sweep", "runs", "wall s", "runs' own wall s", "cpu s", "all completed",
              "same runs.csv"]  # fmt: skip
    print_aligned([header, *table], left={0})
    summary = {}
    for way in (LOCAL, CLUSTER):
        walls = [r["wall_s"] for r in rows if r["way"] == way]
        cpus = [r["cpu_s"] for r in rows if r["way"] == way and r["cpu_s"] is not None]
        summary[way] = {
            "wall_median_s": round(statistics.median(walls), 2),
            "wall_min_s": min(walls),
            "cpu_median_s": round(statistics.median(cpus), 2) if cpus else None,
        }
    local, cluster = summary[LOCAL], summary[CLUSTER]
    ratio = cluster["wall_median_s"] / local["wall_median_s"]
    fastest = cluster["wall_min_s"] / local["wall_min_s"]
    print()
    print(f"median wall: local {local['wall_median_s']:.2f} s, cluster "
          f"{cluster['wall_median_s']:.2f} s: overhead {100 * (ratio - 1):+.1f}% "
          f"(fastest of each: {100 * (fastest - 1):+.1f}%)")  # fmt: skip
    if local["cpu_median_s"] is not None and cluster["cpu_median_s"] is not None:
        extra = cluster["cpu_median_s"] - local["cpu_median_s"]
        print(f"median CPU: local {local['cpu_median_s']:.2f} s, cluster "
              f"{cluster['cpu_median_s']:.2f} s ({extra:+.2f} s)")  # fmt: skip
    print(f"load average (1 min) when it started: {load:.2f} on {os.cpu_count()} cores")
    for row in rows:
        print(json.dumps({"bench": "sweep", **row}))
    print(json.dumps({"bench": "sweep", "summary": summary, "overhead": round(ratio - 1, 3)}))
    verdict = "met" if ratio <= OVERHEAD_TARGET else "NOT met"
    print(f"target: the cluster's median wall at most {OVERHEAD_TARGET:.2f}x local: "
          f"{ratio:.2f}x, {verdict}")  # fmt: skip
    failed = [r for r in rows if not (r["completed"] and r["identical"])]
    return 1 if failed or ratio > OVERHEAD_TARGET else 0


if __name__ == "__main__":
    sys.exit(main())
