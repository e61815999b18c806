"""Scale: the Fire Brigade with 25 to 10,000 Transporters, virtual time, in-memory transport.

Not a framework-against-baseline comparison like the other benchmarks, and not part
of ``python -m benchmarks`` (the largest swarm takes minutes)::

    python -m benchmarks.scale [--counts 25,250,2500,10000] [--runs 3] [--long 60]

Each count runs ``apps/fire_brigade/scenarios/scale_<count>.toml`` (the thesis's
§5.8.2 world repeated once per 25 Transporters; see the files' headers) in a fresh
Python process, so that every run's peak resident memory is its own. The child
times the run itself (``run_scenario``, from building the swarm to the results),
not the interpreter's start-up, and reads its peak RSS (``ru_maxrss``) at the end.
A count is run ``--runs`` times and the median reported, except when its first run
took longer than ``--long`` seconds: then once.

Figures per count: robots (Transporters and stations), wall seconds, simulated
seconds, wall seconds per simulated second, messages per wall second (every
internal and external message sent, as ``results.json`` counts them; with the
in-memory transport and no faults each is delivered and handled, which the run
checks: no protocol errors), peak RSS, RSS per robot (the peak minus what the
child held before building the swarm, over the robots), and the growth of the
wall time from the previous count.

Targets (exit status 1 when one fails, or a run does not complete):

* linear growth: the wall time per robot per simulated second at the largest
  count is at most ``LINEAR_LIMIT`` (1.5) times that at 250 (checked when both
  were run);
* the thesis's §5.8.2 scenario (``thesis_5_8_2.toml``, virtual time) runs in less
  than ``THESIS_LIMIT`` (0.5) wall seconds: the median of ``max(--runs, 5)`` runs,
  each in a fresh process, timed as above.

The result is one table and exactly one JSON line per count and one for the
thesis run on stdout; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final

from ._table import print_aligned

ROOT: Final = Path(__file__).resolve().parent.parent
SCENARIOS: Final = ROOT / "apps" / "fire_brigade" / "scenarios"
THESIS: Final = SCENARIOS / "thesis_5_8_2.toml"
COUNTS: Final = (25, 250, 2500, 10000)
REFERENCE_COUNT: Final = 250  # the linear-growth check compares the largest count with it
LINEAR_LIMIT: Final = 1.5
THESIS_LIMIT: Final = 0.5  # wall seconds
THESIS_RUNS: Final = 5  # at least
FORCED: Final = ("run.virtual=true", 'run.transport="memory"')
KIB: Final = 1024


def scenario_path(count: int) -> Path:
    """The shipped scale scenario with ``count`` Transporters."""
    return SCENARIOS / f"scale_{count}.toml"


# -- the child: one run, measured from inside ---------------------------------------------


def run_child(path: str) -> dict[str, Any]:
    """Runs one scenario in this process and returns what it measured (see the module docs)."""
    import cas_async
    from cas_async.scenario import load_scenario, run_scenario

    scenario = load_scenario(path, FORCED)
    # What this process holds before the swarm exists: the interpreter, numpy, the app.
    before_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    started = time.perf_counter()
    result, _trace = cas_async.run(run_scenario(scenario), virtual=True)
    wall = time.perf_counter() - started
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # Linux: KiB
    return {
        "scenario": Path(path).stem,
        "status": str(result.status),
        "error": result.error,
        "robots": sum(len(ids) for ids in result.groups.values()),
        "groups": {label: len(ids) for label, ids in result.groups.items()},
        "delivered": result.delivered,
        "target": result.target,
        "makespan": result.makespan,
        "sim_time": result.sim_time,
        "wall": wall,
        "messages": sum(result.messages_internal.values()) + sum(result.messages_external.values()),
        "protocol_errors": sum(result.protocol_errors.values()),
        "rss_before_kib": before_kib,
        "rss_peak_kib": peak_kib,
    }


def measure(path: Path) -> dict[str, Any]:
    """One run of ``path`` in a fresh process; what the child measured.

    Raises:
        RuntimeError: the child failed (its stderr is in the message).
    """
    done = subprocess.run(
        [sys.executable, "-m", "benchmarks.scale", "--child", str(path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or len(lines) != 1:
        raise RuntimeError(
            f"the run of {path.name} failed (exit {done.returncode}):\n{done.stderr.strip()}"
        )
    figures: dict[str, Any] = json.loads(lines[0])
    return figures


# -- the parent: runs, medians, the report ------------------------------------------------


def _median_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The run of median wall time (the lower one of an even number of runs)."""
    ordered = sorted(runs, key=lambda r: float(r["wall"]))
    return ordered[(len(ordered) - 1) // 2]


def scale_row(count: int, runs: int, long: float) -> dict[str, Any]:
    """Runs the scale scenario of ``count`` and summarises it (one JSON line's worth)."""
    path = scenario_path(count)
    done: list[dict[str, Any]] = []
    while len(done) < runs:
        figures = measure(path)
        done.append(figures)
        print(
            f"  scale {count} run {len(done)}: {figures['wall']:.2f} s wall, "
            f"{figures['sim_time']:.1f} s simulated, {figures['status']}, "
            f"peak {figures['rss_peak_kib'] / KIB:,.0f} MiB",
            file=sys.stderr,
        )
        if figures["wall"] > long:
            break  # a long run is measured once
    median = _median_run(done)
    wall = statistics.median(float(r["wall"]) for r in done)
    robots, sim = int(median["robots"]), float(median["sim_time"])
    peak = float(median["rss_peak_kib"])
    completed = all(r["status"] == "completed" and r["protocol_errors"] == 0 for r in done)
    return {
        "name": "scale",
        "scenario": path.name,
        "transporters": count,
        "robots": robots,
        "runs": len(done),
        "wall_s": round(wall, 3),
        "sim_s": round(sim, 3),
        "wall_per_sim_s": round(wall / sim, 4) if sim else None,
        "messages": int(median["messages"]),
        "messages_per_wall_s": round(int(median["messages"]) / wall, 1),
        "peak_rss_mib": round(peak / KIB, 1),
        "rss_per_robot_kib": round((peak - float(median["rss_before_kib"])) / robots, 2),
        "wall_per_robot_sim_s_us": round(1e6 * wall / (robots * sim), 3) if sim else None,
        "completed": completed,
        "wall_runs": [round(float(r["wall"]), 3) for r in done],
    }


def thesis_row(runs: int) -> dict[str, Any]:
    """The §5.8.2 thesis scenario on virtual time: median wall of ``runs`` fresh runs."""
    done = [measure(THESIS) for _ in range(runs)]
    walls = [float(r["wall"]) for r in done]
    wall = statistics.median(walls)
    print(f"  thesis_5_8_2: {', '.join(f'{w:.3f}' for w in walls)} s", file=sys.stderr)
    completed = all(r["status"] == "completed" for r in done)
    return {
        "name": "scale_thesis",
        "scenario": THESIS.name,
        "robots": int(done[0]["robots"]),
        "runs": runs,
        "wall_s": round(wall, 4),
        "sim_s": round(float(_median_run(done)["sim_time"]), 3),
        "target": f"< {THESIS_LIMIT} s",
        "completed": completed,
        "passed": completed and wall < THESIS_LIMIT,
        "wall_runs": [round(w, 4) for w in walls],
    }


def judge(rows: list[dict[str, Any]]) -> None:
    """Adds each row's growth and verdict; the largest count carries the linear check."""
    previous: dict[str, Any] | None = None
    reference = next((r for r in rows if r["transporters"] == REFERENCE_COUNT), None)
    largest = max(rows, key=lambda r: int(r["transporters"]))
    for row in rows:
        row["growth"] = round(row["wall_s"] / previous["wall_s"], 2) if previous else None
        row["passed"] = bool(row["completed"])
        if row is largest and reference is not None and row is not reference:
            ratio = row["wall_per_robot_sim_s_us"] / reference["wall_per_robot_sim_s_us"]
            row["linear_ratio"] = round(ratio, 3)
            row["target"] = f"per-robot cost <= {LINEAR_LIMIT}x that at {REFERENCE_COUNT}"
            row["passed"] = row["passed"] and ratio <= LINEAR_LIMIT
        previous = row


def print_table(rows: Sequence[dict[str, Any]], thesis: dict[str, Any] | None) -> None:
    """The counts as one aligned table, then the thesis line."""
    header = ("transporters", "robots", "wall s", "sim s", "wall/sim", "msg/s", "peak MiB",
              "KiB/robot", "growth", "us/robot-sim-s", "pass")  # fmt: skip
    lines = [header]
    for r in rows:
        growth = "" if r["growth"] is None else f"{r['growth']:.2f}x"
        lines.append((f"{r['transporters']:,}", f"{r['robots']:,}", f"{r['wall_s']:,.2f}",
                      f"{r['sim_s']:.1f}", f"{r['wall_per_sim_s']:.3f}",
                      f"{r['messages_per_wall_s']:,.0f}", f"{r['peak_rss_mib']:,.0f}",
                      f"{r['rss_per_robot_kib']:.1f}", growth,
                      f"{r['wall_per_robot_sim_s_us']:.1f}",
                      "PASS" if r["passed"] else "FAIL"))  # fmt: skip
    print_aligned(lines)
    checked = [r for r in rows if "linear_ratio" in r]
    for r in checked:
        print(
            f"linear growth: per-robot cost at {r['transporters']:,} is {r['linear_ratio']:.2f}x "
            f"that at {REFERENCE_COUNT} (target <= {LINEAR_LIMIT}x)"
        )
    if thesis is not None:
        verdict = "PASS" if thesis["passed"] else "FAIL"
        print(
            f"thesis_5_8_2 --virtual: {thesis['wall_s']:.3f} s wall, median of "
            f"{thesis['runs']} (target < {THESIS_LIMIT} s) {verdict}"
        )


def _counts(text: str) -> list[int]:
    try:
        counts = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected counts such as 25,250, got {text!r}") from None
    missing = [c for c in counts if not scenario_path(c).is_file()]
    if not counts or missing:
        raise argparse.ArgumentTypeError(
            f"no scale scenario for {missing or text!r}: choose among {', '.join(map(str, COUNTS))}"
        )
    return counts


def main(argv: Sequence[str] | None = None) -> int:
    """The command line; returns the exit status (0: every target met)."""
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.scale", description="Fire Brigade at scale, virtual time"
    )
    parser.add_argument("--counts", type=_counts, default=list(COUNTS), help="e.g. 25,250,2500")
    parser.add_argument("--runs", type=int, default=3, help="runs per count (default 3)")
    parser.add_argument(
        "--long", type=float, default=60.0, help="a count whose first run is longer runs once"
    )
    parser.add_argument("--no-thesis", action="store_true", help="skip the §5.8.2 timing")
    parser.add_argument("--child", metavar="SCENARIO", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(run_child(args.child)))
        return 0
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    rows = [scale_row(count, args.runs, args.long) for count in sorted(args.counts)]
    judge(rows)
    thesis = None if args.no_thesis else thesis_row(max(args.runs, THESIS_RUNS))
    print()
    print_table(rows, thesis)
    print()
    for row in rows:
        print(json.dumps(row))
    if thesis is not None:
        print(json.dumps(thesis))
    passed = all(r["passed"] for r in rows) and (thesis is None or thesis["passed"])
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
