"""Fire Brigade scenarios over many seeds: makespan spread and bucket figures in one table.

Usage::

    python -m apps.fire_brigade.sweep [SCENARIO ...] [--seeds N] [--set KEY=VALUE ...] [--json]

Each scenario (by default the six thesis scenarios, ``thesis_*.toml``; the
``scale_*`` ones are for ``python -m benchmarks.scale``) runs once per seed ``1..N`` on
virtual time with the in-memory transport, whatever its ``[run]`` table says.
Makespan figures are over the runs that completed; bucket figures pool every
bucket delivered in those runs; wall seconds add up every run's own wall time.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import cas_async
from cas_async.scenario import RunResult, RunStatus, ScenarioError, load_scenario, run_scenario

from .config import FireBrigadeConfig

__all__ = ["SCENARIOS", "SweepRow", "main", "sweep", "sweep_table"]

SCENARIOS: Final = Path(__file__).resolve().parent / "scenarios"
"""Where the shipped scenarios are; the sweep runs the thesis's by default."""
_THESIS: Final = "thesis_*.toml"

_FORCED: Final = ("run.virtual=true", 'run.transport="memory"')
_COLUMNS: Final = (
    ("scenario", "<22"), ("strategy", "<8"), ("runs", ">6"), ("mean", ">7"), ("std", ">6"),
    ("min", ">7"), ("median", ">7"), ("max", ">7"), ("hand-overs", ">10"),
    ("travel", ">7"), ("wall s", ">7"),
)  # fmt: skip
_GROUPS: Final = ((0, 3), (3, 8), (8, 10))


@dataclass(frozen=True, slots=True)
class SweepRow:
    """One scenario over its seeds. Times are simulated seconds unless named ``wall``.

    Attributes:
        scenario: the scenario file's stem (``thesis_5_8_2``).
        strategy: the partner strategy's name.
        completed: runs that reached the mission's target.
        runs: runs made.
        makespan_mean: mean makespan of the completed runs (``None`` if none completed).
        makespan_std: sample standard deviation (0 for a single completed run).
        makespan_min: shortest makespan.
        makespan_median: median makespan.
        makespan_max: longest makespan.
        handovers_mean: mean hand-overs per delivered bucket, the last one to a sink included.
        travel_mean: mean bucket travel time, creation to delivery.
        wall: wall seconds of all runs together.
        incomplete: ``"seed N: status"`` for each run that did not complete, with its error.
    """

    scenario: str
    strategy: str
    completed: int
    runs: int
    makespan_mean: float | None
    makespan_std: float | None
    makespan_min: float | None
    makespan_median: float | None
    makespan_max: float | None
    handovers_mean: float | None
    travel_mean: float | None
    wall: float
    incomplete: tuple[str, ...] = ()


def sweep(scenario: str | Path, seeds: int, overrides: Sequence[str] = ()) -> SweepRow:
    """Runs ``scenario`` for seeds ``1..seeds`` and summarises the runs.

    Args:
        scenario: the scenario file.
        seeds: how many seeds, at least 1.
        overrides: ``--set`` texts, applied before the sweep's own (virtual time,
            memory transport, the seed), which win.

    Raises:
        ScenarioError: the scenario or an override is invalid.
        ValueError: ``seeds`` is less than 1.
    """
    if seeds < 1:
        raise ValueError(f"seeds must be at least 1, got {seeds}")
    results: list[RunResult] = []
    strategy = "?"
    for seed in range(1, seeds + 1):
        loaded = load_scenario(scenario, [*overrides, *_FORCED, f"run.seed={seed}"])
        if isinstance(loaded.config, FireBrigadeConfig):
            strategy = loaded.config.strategy.name
        result, _trace = cas_async.run(run_scenario(loaded), virtual=True)
        results.append(result)
    done = [r for r in results if r.status is RunStatus.COMPLETED]
    spans = [r.makespan for r in done if r.makespan is not None]
    handovers = [float(n) for r in done for n in r.handovers_per_item]
    travel = [t for r in done for t in r.travel_times]
    return SweepRow(
        scenario=Path(scenario).stem,
        strategy=strategy,
        completed=len(done),
        runs=len(results),
        makespan_mean=statistics.fmean(spans) if spans else None,
        makespan_std=(statistics.stdev(spans) if len(spans) > 1 else 0.0) if spans else None,
        makespan_min=min(spans, default=None),
        makespan_median=statistics.median(spans) if spans else None,
        makespan_max=max(spans, default=None),
        handovers_mean=statistics.fmean(handovers) if handovers else None,
        travel_mean=statistics.fmean(travel) if travel else None,
        wall=sum(r.wall_time for r in results),
        incomplete=tuple(
            f"seed {r.seed}: {r.status}" + (f": {r.error}" if r.error else "")
            for r in results
            if r.status is not RunStatus.COMPLETED
        ),
    )


def sweep_table(rows: Sequence[SweepRow]) -> str:
    """``rows`` as a plain-text table: one line per scenario under a two-line header."""
    header = "".join(f"{name:{spec}} " for name, spec in _COLUMNS).rstrip()
    # group titles over columns 3-7 and 8-9; a column is its width plus one space
    lead, span, bucket = (sum(int(spec[1:]) + 1 for _, spec in _COLUMNS[a:b]) for a, b in _GROUPS)
    over = (
        f"{'':{lead}} {' makespan, simulated s ':-^{span - 1}} {' mean per bucket ':-^{bucket - 1}}"
    )
    lines = [over, header, "-" * len(header)]
    for row in rows:
        figures = (row.makespan_mean, row.makespan_std, row.makespan_min, row.makespan_median,
                   row.makespan_max, row.handovers_mean, row.travel_mean)  # fmt: skip
        cells = (row.scenario, row.strategy, f"{row.completed}/{row.runs}",
                 *map(_number, figures), f"{row.wall:.1f}")  # fmt: skip
        lines.append("".join(f"{c:{spec}} " for c, (_, spec) in zip(cells, _COLUMNS, strict=True)))
    return "\n".join(line.rstrip() for line in lines)


def _number(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.1f}"


def main(argv: Sequence[str] | None = None) -> int:
    """The command line; returns the exit status (2 for an invalid scenario or argument)."""
    parser = argparse.ArgumentParser(prog="python -m apps.fire_brigade.sweep", description=__doc__)
    parser.add_argument("scenarios", nargs="*", metavar="SCENARIO", help="scenario files")
    parser.add_argument("--seeds", type=int, default=20, help="run seeds 1..N (default 20)")
    parser.add_argument("--set", action="append", default=[], dest="overrides", metavar="KEY=VALUE")
    parser.add_argument("--json", action="store_true", help="one JSON object per scenario")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds must be at least 1, got {args.seeds}")
    paths = args.scenarios or sorted(SCENARIOS.glob(_THESIS))
    rows: list[SweepRow] = []
    for path in paths:
        try:
            row = sweep(path, args.seeds, args.overrides)
        except ScenarioError as error:
            print(f"error: {error}", file=sys.stderr)
            return 2
        rows.append(row)
        if args.json:  # a line per scenario as soon as it is done: long sweeps show progress
            print(json.dumps(dataclasses.asdict(row)), flush=True)
    if not args.json:
        print(sweep_table(rows))
        for row in rows:  # the table only counts them: say which seeds, and why
            for problem in row.incomplete:
                print(f"{row.scenario} {problem}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
