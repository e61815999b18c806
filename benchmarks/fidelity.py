"""Time-factor fidelity: does a scaled real-time run reach what virtual time reaches?

Issue 5: with the scaled clock at factors 10 and 100, the mean makespan of the
thesis scenario over 20 seeds is within 5% of virtual time; and the curve up to
the factor where it breaks. Not part of ``python -m benchmarks`` (it lasts minutes)::

    python -m benchmarks.fidelity [--seeds 20] [--factors 10,20,50,100,200,500,1000]
        [--scenario apps/fire_brigade/scenarios/thesis_5_8_2.toml]
        [--transport udp|memory|both] [--jobs 1] [--loop default|stdlib|uvloop]

Every seed runs once in virtual time (memory transport: the reference) and once
per factor and transport on :class:`~cas_async.ScaledClock`, through
``run_scenario`` as the CLI runs it. Runs go to worker processes (``--jobs``, one
by default: the machine's other work, and a second run, delay a scaled run's
messages, which the time factor turns into simulated seconds). Factors are taken
in increasing order until the mean error has passed 5% on every transport and
every target factor has been measured: where the error first passes 5% is the
"break". A scaled run not finished by ``--max-time`` simulated seconds (default:
four times the slowest virtual makespan) counts as incomplete; a factor with an
incomplete run fails.

Judged: the first transport given (UDP by default, as shipped); the other is
noted. One table, and one JSON line per factor and transport plus a summary line,
on stdout; progress on stderr. Exit status: 0 every target factor within 5%, 1 not.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import statistics
import sys
import time
from collections import Counter
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from multiprocessing import get_context

from ._table import print_aligned

SCENARIO = "apps/fire_brigade/scenarios/thesis_5_8_2.toml"
FACTORS = (10, 20, 50, 100, 200, 500, 1000)
TARGETS = (10, 100)
TOLERANCE = 0.05  # of the virtual mean
MAX_TIME_MARGIN = 4.0  # times the slowest virtual makespan


@dataclass(frozen=True)
class Run:
    """One run's outcome (``factor`` is ``None`` for virtual time)."""

    seed: int
    factor: float | None
    transport: str
    status: str
    makespan: float | None
    wall_s: float
    exchanges: int
    dropped: int  # messages the runtime dropped (duplicates of re-sent requests, mostly)


def _quiet() -> None:
    # Late replies under load are dropped as duplicates and logged one by one: keep
    # them out of the report (they are counted in Run.dropped).
    logging.getLogger("cas_async").setLevel(logging.ERROR)


def run_one(
    scenario: str,
    seed: int,
    factor: float | None,
    transport: str,
    max_time: float | None,
    use_uvloop: bool | None,
) -> Run:
    """Runs the scenario once (in a worker process) and returns what it measured."""
    import cas_async  # imported in the worker: the parent only collects results
    from cas_async.scenario import load_scenario, run_scenario

    overrides = [f"run.seed={seed}", f"run.transport={transport}"]
    if factor is None:
        overrides.append("run.virtual=true")
    else:
        overrides += ["run.virtual=false", f"run.time_factor={factor}"]
    if max_time is not None:
        overrides.append(f"run.max_time={max_time}")
    loaded = load_scenario(scenario, overrides)
    result, _ = cas_async.run(run_scenario(loaded), virtual=factor is None, use_uvloop=use_uvloop)
    return Run(
        seed,
        factor,
        transport,
        result.status.value,
        result.makespan,
        round(result.wall_time, 3),
        result.exchanges,
        sum(result.protocol_errors.values()),
    )


def summarise(
    factor: float, transport: str, virtual: list[Run], scaled: list[Run]
) -> dict[str, object]:
    """The row of one factor and transport: means, spreads, relative error of the mean."""
    reference = [r.makespan for r in virtual if r.makespan is not None]
    done = [r.makespan for r in scaled if r.makespan is not None]
    mean_virtual = statistics.fmean(reference)
    mean_scaled = statistics.fmean(done) if done else None
    error = None if mean_scaled is None else (mean_scaled - mean_virtual) / mean_virtual
    incomplete = len(scaled) - len(done)
    # Timed out (too slow for the factor) or failed (a layer raised: a bug to look at).
    endings = Counter(r.status for r in scaled if r.makespan is None)
    return {
        "name": "fidelity",
        "factor": factor,
        "transport": transport,
        "seeds": len(scaled),
        "incomplete": incomplete,
        "incomplete_by_status": dict(sorted(endings.items())),
        "mean_virtual": round(mean_virtual, 3),
        "mean_scaled": None if mean_scaled is None else round(mean_scaled, 3),
        "error": None if error is None else round(error, 4),
        "sd_virtual": round(statistics.stdev(reference), 3) if len(reference) > 1 else 0.0,
        "sd_scaled": round(statistics.stdev(done), 3) if len(done) > 1 else 0.0,
        "min_scaled": round(min(done), 3) if done else None,
        "max_scaled": round(max(done), 3) if done else None,
        "wall_per_run_s": round(statistics.fmean(r.wall_s for r in scaled), 3),
        "dropped_per_run": round(statistics.fmean(r.dropped for r in scaled), 1),
        "within": incomplete == 0 and error is not None and abs(error) <= TOLERANCE,
    }


def _number(value: object, form: str) -> str:
    return "-" if value is None else form.format(value)


def print_table(rows: Sequence[dict[str, object]]) -> None:
    lines = [("factor", "transport", "runs", "mean virtual s", "mean scaled s", "error",
              "sd virtual", "sd scaled", "wall/run s", "dropped/run", "within 5%")]  # fmt: skip
    for r in rows:
        done = f"{r['seeds'] - r['incomplete']}/{r['seeds']}"  # type: ignore[operator]
        lines.append((
            f"{r['factor']:g}", str(r["transport"]), done, f"{r['mean_virtual']:.2f}",
            _number(r["mean_scaled"], "{:.2f}"), _number(r["error"], "{:+.1%}"),
            f"{r['sd_virtual']:.2f}", f"{r['sd_scaled']:.2f}", f"{r['wall_per_run_s']:.2f}",
            f"{r['dropped_per_run']:.1f}", "yes" if r["within"] else "NO",
        ))  # fmt: skip
    print_aligned(lines, left=(1,))


def _factors(text: str) -> list[float]:
    try:
        factors = sorted({float(part) for part in text.split(",") if part.strip()})
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected factors like 10,100, got {text!r}") from None
    if not factors or factors[0] <= 0:
        raise argparse.ArgumentTypeError(f"factors must be positive, got {text!r}")
    return factors


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="cas_async fidelity: scaled real time against virtual time (makespan)"
    )
    parser.add_argument("--seeds", type=int, default=20, help="seeds 1..N (default 20)")
    parser.add_argument(
        "--factors",
        type=_factors,
        default=list(map(float, FACTORS)),
        help="time factors, taken in increasing order, with the targets added "
        "(default 10,20,50,100,200,500,1000)",
    )
    parser.add_argument(
        "--targets",
        type=_factors,
        default=list(map(float, TARGETS)),
        help="factors that must be within 5%% (default 10,100)",
    )
    parser.add_argument("--scenario", default=SCENARIO, help=f"default {SCENARIO}")
    parser.add_argument(
        "--transport",
        choices=["udp", "memory", "both"],
        default="both",
        help="scaled runs' transport; with both, UDP (as shipped) is judged, memory noted",
    )
    parser.add_argument("--jobs", type=int, default=1, help="runs at once (default 1)")
    parser.add_argument(
        "--loop",
        choices=["default", "stdlib", "uvloop"],
        default="default",
        help="scaled runs' event loop; default: as cas_async.run picks it (uvloop if installed)",
    )
    parser.add_argument(
        "--max-time",
        type=float,
        default=None,
        help="simulated seconds after which a scaled run is incomplete "
        f"(default {MAX_TIME_MARGIN:g} x the slowest virtual makespan)",
    )
    parser.add_argument("--all", action="store_true", help="run every factor, also past the break")
    args = parser.parse_args(argv)
    if args.seeds < 2 or args.jobs < 1:
        parser.error("--seeds must be at least 2, --jobs at least 1")
    transports = ["udp", "memory"] if args.transport == "both" else [args.transport]
    use_uvloop = {"default": None, "stdlib": False, "uvloop": True}[args.loop]
    seeds = range(1, args.seeds + 1)
    factors = sorted({*args.factors, *args.targets})  # the targets are always measured
    load_before = os.getloadavg()
    started = time.perf_counter()
    context = get_context("spawn")  # a clean interpreter: nothing inherited from this one
    with ProcessPoolExecutor(args.jobs, mp_context=context, initializer=_quiet) as pool:

        def batch(factor: float | None, transport: str, max_time: float | None) -> list[Run]:
            jobs = [
                pool.submit(run_one, args.scenario, s, factor, transport, max_time, use_uvloop)
                for s in seeds
            ]
            return [job.result() for job in jobs]

        virtual = batch(None, "memory", None)
        bad = [r for r in virtual if r.makespan is None]
        if bad:
            print(f"fidelity: virtual runs did not complete: {bad}", file=sys.stderr)
            return 1
        slowest = max(r.makespan for r in virtual if r.makespan is not None)
        max_time = args.max_time or round(MAX_TIME_MARGIN * slowest, 1)
        mean = statistics.fmean(r.makespan for r in virtual if r.makespan is not None)
        print(
            f"  fidelity: virtual mean makespan {mean:.2f} s over {args.seeds} seeds "
            f"(slowest {slowest:.2f} s); scaled runs stop at {max_time:g} s",
            file=sys.stderr,
        )
        rows: list[dict[str, object]] = []
        broken: set[str] = set()
        for factor in factors:
            targets_left = any(t >= factor for t in args.targets)
            if not args.all and not targets_left and broken.issuperset(transports):
                break  # past the break everywhere: the curve is known
            for transport in transports:
                row = summarise(factor, transport, virtual, batch(factor, transport, max_time))
                rows.append(row)
                if not row["within"]:
                    broken.add(transport)
                print(
                    f"  fidelity: factor {factor:g} {transport}: mean "
                    f"{_number(row['mean_scaled'], '{:.2f}')} s "
                    f"({_number(row['error'], '{:+.1%}')}), {row['incomplete']} incomplete",
                    file=sys.stderr,
                )
    judged = transports[0]
    verdicts = [
        r["within"] for r in rows if r["transport"] == judged and r["factor"] in args.targets
    ]
    breaks = {
        t: next((r["factor"] for r in rows if r["transport"] == t and not r["within"]), None)
        for t in transports
    }
    summary = {
        "name": "fidelity_summary",
        "scenario": args.scenario,
        "seeds": args.seeds,
        "loop": args.loop,
        "judged": judged,
        "targets": args.targets,
        "break": breaks,  # the first factor whose mean error passed 5% (None: none did)
        "virtual_makespans": [r.makespan for r in virtual],
        "load_before": [round(x, 2) for x in load_before],
        "load_after": [round(x, 2) for x in os.getloadavg()],
        "wall_s": round(time.perf_counter() - started, 1),
        "ok": bool(verdicts) and all(verdicts),
    }
    print()
    print_table(rows)
    print()
    for row in rows:
        print(json.dumps(row))
    print(json.dumps(summary))
    return 0 if summary["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
