"""A sweep's outputs: ``runs.csv``, ``table.md``, ``summary.json`` and box plots.

* ``runs.csv``: a row per finished run: the varied keys, ``seed``, ``status``,
  ``error``, then every metric (full precision; empty where the run has none);
  see :mod:`._runs_file`, which also writes it as the runs finish.
* ``table.md``: one markdown table, a row per metric and point (metrics in the
  order first seen, points in grid order): n, mean, std, min, median, max over the
  completed runs, with a line above saying what was run and one below naming the
  runs left out.
* ``summary.json``: the same numbers, unrounded, the incomplete runs, and how
  the sweep went (runs resumed, workers lost, where it ran, why it ended early).
* ``box_<metric>.png``: a box per point, over the completed runs (see :func:`write_box_plots`).

Every file is written whole or not at all.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any, Final

from ..output._atomic_files import atomic_text_file
from ..output._results import RunStatus
from ._outcome import SweepOutcome, SweepRun
from ._runs_file import write_runs_csv

__all__ = [
    "format_number",
    "sweep_summary",
    "sweep_table",
    "write_sweep_files",
]

_FIGURES: Final = ("mean", "std", "min", "median", "max")
_SMALL: Final = 1e-3
"""Below this (in magnitude) a figure is shown in exponent notation: ``1.2e-05``."""


def format_number(value: float | None) -> str:
    """``value`` to three significant digits: ``28.1``, ``0.412``, ``5.90``, ``169``.

    Whole numbers have no decimals (``20``, ``1234``; 1234.5 is ``1234``), values
    under 0.001 an exponent (``1.20e-05``), and ``None`` is ``n/a``.
    """
    if value is None:
        return "n/a"
    if not math.isfinite(value):
        return str(value)
    if value == round(value) and abs(value) < 1e15:
        return f"{value:.0f}"
    if abs(value) < _SMALL:
        return f"{value:.2e}"
    # the decimals of three significant digits, once rounded: 0.9999 is 1.00, not 1.000
    rounded = abs(float(f"{value:.3g}"))
    return f"{value:.{max(0, 2 - math.floor(math.log10(rounded)))}f}"


def sweep_table(outcome: SweepOutcome) -> str:
    """``table.md``'s text: a line on what ran, the markdown table, the runs left out."""
    plan = outcome.plan
    keys = [axis.key for axis in plan.axes]
    header = [*keys, "metric", "runs", *_FIGURES]
    stats = outcome.statistics()
    totals = [len(runs) for runs in outcome.by_point()]
    rows = []
    for metric in outcome.metrics:
        for point, by_metric in enumerate(stats):
            figures = by_metric[metric]
            total = totals[point]
            rows.append(
                [
                    *plan.labels(point),
                    metric,
                    f"{figures.n}/{total}",
                    *(format_number(getattr(figures, name)) for name in _FIGURES),
                ]
            )
    right = len(keys) + 1  # the columns from "runs" on are numbers: aligned right
    lines = [_intro(outcome), ""]
    lines += _markdown(header, rows, right) if rows else ["(no run finished)"]
    if outcome.incomplete:
        left_out = ", ".join(f"{_name(outcome, run)} ({run.status})" for run in outcome.incomplete)
        lines += ["", f"Not in the figures: {left_out}."]
    return "\n".join(lines) + "\n"


def _intro(outcome: SweepOutcome) -> str:
    plan = outcome.plan
    settings = (
        f" ({' '.join(f'--set {text}' for text in plan.overrides)})" if plan.overrides else ""
    )
    seeds = "seed 1" if plan.seeds == 1 else f"seeds 1-{plan.seeds}"
    done = len(outcome.runs)
    completed = done - len(outcome.incomplete)
    ran = f"{done} of {plan.runs} runs (interrupted)" if outcome.interrupted else f"{done} runs"
    failed, timed_out = _count(outcome, RunStatus.FAILED), _count(outcome, RunStatus.TIMED_OUT)
    stopped = _count(outcome, RunStatus.STOPPED)
    verdict = "all completed" if completed == done else f"{completed} completed"
    verdict += f", {failed} failed" if failed else ""
    verdict += f", {stopped} stopped" if stopped else ""
    verdict += f", {timed_out} timed out" if timed_out else ""
    return (
        f"Sweep of {plan.path.name}{settings}, {seeds}, {len(plan.points)} grid point"
        f"{'s' if len(plan.points) != 1 else ''}: {ran}, {verdict}. "
        "Figures are over the completed runs only; times in simulated seconds, "
        "wall_time in wall seconds."
    )


def _markdown(header: Sequence[str], rows: Sequence[Sequence[str]], right: int) -> list[str]:
    cells = [[cell.replace("|", r"\|") for cell in row] for row in [header, *rows]]
    widths = [max(3, *(len(row[k]) for row in cells)) for k in range(len(header))]

    def line(row: Sequence[str]) -> str:
        padded = (
            f"{cell:>{width}}" if k >= right else f"{cell:<{width}}"
            for k, (cell, width) in enumerate(zip(row, widths, strict=True))
        )
        return "| " + " | ".join(padded) + " |"

    rule = [("-" * (w - 1) + ":") if k >= right else "-" * w for k, w in enumerate(widths)]
    return [line(cells[0]), line(rule), *(line(row) for row in cells[1:])]


def _name(outcome: SweepOutcome, run: SweepRun) -> str:
    where = outcome.plan.describe(run.point)
    return f"{where} seed {run.seed}" if where else f"seed {run.seed}"


def sweep_summary(outcome: SweepOutcome) -> dict[str, Any]:
    """``summary.json``'s data: the sweep, per point per metric its statistics, what failed."""
    plan = outcome.plan
    stats = outcome.statistics()
    groups = outcome.by_point()
    return {
        "scenario": str(plan.path),
        "overrides": list(plan.overrides),
        "seeds": plan.seeds,
        "vary": {axis.key: list(axis.values) for axis in plan.axes},
        "runs": plan.runs,
        "finished": len(outcome.runs),
        "completed": len(outcome.runs) - len(outcome.incomplete),
        "failed": _count(outcome, RunStatus.FAILED),
        "stopped": _count(outcome, RunStatus.STOPPED),
        "timed_out": _count(outcome, RunStatus.TIMED_OUT),
        "interrupted": outcome.interrupted,
        "error": outcome.error,
        "resumed": outcome.resumed,
        "wall_time": outcome.wall_time,
        "jobs": outcome.jobs,
        "ran_on": outcome.ran_on,
        "workers_lost": outcome.workers_lost,
        "runs_resent": outcome.runs_resent,
        "metrics": list(outcome.metrics),
        "points": [
            {
                "values": _values(outcome, point),
                "runs": len(groups[point]),
                "completed": sum(run.completed for run in groups[point]),
                "metrics": {name: asdict(figures) for name, figures in by_metric.items()},
            }
            for point, by_metric in enumerate(stats)
        ],
        "incomplete": [
            {
                "values": _values(outcome, run.point),
                "seed": run.seed,
                "status": str(run.status),
                "error": run.error,
            }
            for run in outcome.incomplete
        ],
    }


def _count(outcome: SweepOutcome, status: RunStatus) -> int:
    return sum(run.status is status for run in outcome.runs)


def _values(outcome: SweepOutcome, point: int) -> dict[str, Any]:
    plan = outcome.plan
    return {axis.key: axis.values[k] for axis, k in zip(plan.axes, plan.points[point], strict=True)}


def write_sweep_files(outcome: SweepOutcome, out_dir: Path) -> list[Path]:
    """Writes ``runs.csv``, ``table.md`` and ``summary.json`` to ``out_dir`` (created).

    Returns:
        The paths written, in that order.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / "runs.csv", out_dir / "table.md", out_dir / "summary.json"]
    write_runs_csv(outcome.plan, outcome.runs, paths[0])
    with atomic_text_file(paths[1]) as stream:
        stream.write(sweep_table(outcome))
    # dates and times of TOML values are the only values JSON has no type for
    text = json.dumps(sweep_summary(outcome), indent=2, ensure_ascii=False, default=str)
    with atomic_text_file(paths[2]) as stream:
        stream.write(text + "\n")
    return paths
