"""A run's results as ``results.json`` and as a plain-text summary table.

``results.json`` holds every :class:`~cas_async.scenario.output._results.RunResult` field
under its own name (status as its string, robot ids as strings in maps) plus a
``statistics`` section computed from them::

    "statistics": {
      "travel_time": {"count": .., "mean": .., "median": .., "p95": .., "min": .., "max": ..},
      "handovers_per_item": {...same keys...},
      "distance": {...same keys..., "total": ..},
      "messages": {"internal": <total>, "external": <total>},
      "protocol_errors": <total>
    }

``metrics``, ``series`` and ``by_exchange`` hold the application's measures of the
robots' positions (one number each, over time, by exchange count), and
``delivery_times`` the instant of each delivery.

``faults`` is ``null`` unless the scenario has a ``[faults]`` table; then it holds
the fault counts (``sent``, ``lost``, ...) and the table gets a ``faults`` line.

``fail_on_drops`` is ``null`` unless the run was asked to fail on drops
(``run --fail-on-drops``); then it lists the reasons (empty: any), and
``failing_drops`` the drops by reason that failed it. ``unanswered`` counts the
internal requests still waiting when the run ended that their asked layer had not
answered (``get_intra_msg_reply`` returned ``None``), by who asked what of whom.

That is a mission of items (``kind`` ``"items"``, the Fire Brigade's). A mission with
an objective of its own has no item fields (``created``, ``exchanges``,
``travel_times``, ``handovers_per_item`` and their statistics); it has ``kind``,
``verb`` and ``samples`` (the objective's values per thing done), each summarised
under ``statistics`` by its name.
"""

from __future__ import annotations

import datetime
import json
import math
import numbers
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final, cast

import numpy as np

from ._atomic_files import atomic_text_file
from ._results import RunResult, RunStatus

__all__ = [
    "plural",
    "results_dict",
    "statistics",
    "summary_table",
    "write_results",
]

_STATUS_WORDS = {
    RunStatus.STOPPED: "STOPPED (every robot stopped before the target)",
    RunStatus.INTERRUPTED: "INTERRUPTED (stopped before the target)",
    RunStatus.TIMED_OUT: "TIMED OUT (max_time reached before the target)",
    RunStatus.FAILED: "FAILED",
}
_LABEL_WIDTH = 22
_VALUE_WIDTH = 20
_LINE_WIDTH = 100


def statistics(values: Sequence[float]) -> dict[str, float | None]:
    """``count, mean, median, p95, min, max`` of ``values``.

    ``median`` averages the two middle values of an even count; ``p95`` is by the
    nearest-rank method (the ``ceil(0.95 n)``-th smallest value). For no values,
    ``count`` is 0 and the rest ``None``.
    """
    ordered = sorted(values)
    n = len(ordered)
    if n == 0:
        return {"count": 0, "mean": None, "median": None, "p95": None, "min": None, "max": None}
    middle = n // 2
    median = ordered[middle] if n % 2 else (ordered[middle - 1] + ordered[middle]) / 2
    rank = -(-95 * n // 100)  # ceil(0.95 n) in integers: 0.95 * 20 must be exactly 19
    return {
        "count": n,
        "mean": math.fsum(ordered) / n,
        "median": median,
        "p95": ordered[rank - 1],
        "min": ordered[0],
        "max": ordered[-1],
    }


def results_dict(result: RunResult) -> dict[str, Any]:
    """Every field of ``result`` plus its ``statistics``, as JSON-ready plain data.

    Identity and outcome come first, then the statistics, then the raw data.
    Maps keyed by robot id have string keys in id order; message and error
    counts are sorted by name; ``groups`` and ``extra`` keep the app's order.
    Values TOML can hold but JSON cannot (dates and times) become ISO strings,
    and numpy scalars Python numbers.
    """
    if result.kind != "items":
        return _objective_dict(result)
    data = {
        "app": result.app,
        "item_name": result.item_name,
        "scenario": result.scenario,
        "seed": result.seed,
        "status": str(result.status),
        "error": result.error,
        "traceback": result.traceback,
        "target": result.target,
        "created": result.created,
        "delivered": result.delivered,
        "exchanges": result.exchanges,
        "makespan": result.makespan,
        "sim_time": result.sim_time,
        "wall_time": result.wall_time,
        "statistics": {
            "travel_time": statistics(result.travel_times),
            "handovers_per_item": statistics(result.handovers_per_item),
            **_common_statistics(result),
        },
        "travel_times": list(result.travel_times),
        "handovers_per_item": list(result.handovers_per_item),
        **_common_data(result),
    }
    return cast(dict[str, Any], _plain(data))


def _objective_dict(result: RunResult) -> dict[str, Any]:
    """:func:`results_dict` of a mission with an objective of its own (no item fields)."""
    data = {
        "app": result.app,
        "item_name": result.item_name,
        "kind": result.kind,
        "verb": result.verb,
        "scenario": result.scenario,
        "seed": result.seed,
        "status": str(result.status),
        "error": result.error,
        "traceback": result.traceback,
        "target": result.target,
        "delivered": result.delivered,
        "makespan": result.makespan,
        "sim_time": result.sim_time,
        "wall_time": result.wall_time,
        "statistics": {
            **{name: statistics(values) for name, values in result.samples.items()},
            **_common_statistics(result),
        },
        "samples": {name: list(values) for name, values in result.samples.items()},
        **_common_data(result),
    }
    return cast(dict[str, Any], _plain(data))


def _common_statistics(result: RunResult) -> dict[str, Any]:
    return {
        "distance": {
            **statistics(list(result.distance.values())),
            "total": math.fsum(result.distance.values()),
        },
        "messages": {
            "internal": sum(result.messages_internal.values()),
            "external": sum(result.messages_external.values()),
        },
        "protocol_errors": sum(result.protocol_errors.values()),
    }


def _common_data(result: RunResult) -> dict[str, Any]:
    distance = {str(robot_id): result.distance[robot_id] for robot_id in sorted(result.distance)}
    return {
        "distance": distance,
        "messages_internal": dict(sorted(result.messages_internal.items())),
        "messages_external": dict(sorted(result.messages_external.items())),
        "protocol_errors": dict(sorted(result.protocol_errors.items())),
        "fail_on_drops": None if result.fail_on_drops is None else list(result.fail_on_drops),
        "failing_drops": dict(result.failing_drops),
        "unanswered": dict(result.unanswered),
        "faults": None if result.faults is None else dict(result.faults),
        "groups": {label: list(ids) for label, ids in result.groups.items()},
        "extra": dict(result.extra),
        "metrics": dict(result.metrics),
        "delivery_times": list(result.delivery_times),
        "series": {name: dict(series) for name, series in result.series.items()},
        "by_exchange": {name: dict(series) for name, series in result.by_exchange.items()},
        "config": result.config,
    }


def _plain(value: Any) -> Any:
    """``value`` in JSON types.

    TOML dates and times become ISO strings, tuples lists, and numpy scalars
    (which an app's figures may be) Python numbers.
    """
    if isinstance(value, Mapping):
        return {str(key): _plain(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(item) for item in value]
    if isinstance(value, datetime.date | datetime.time):
        return value.isoformat()
    if isinstance(value, np.generic):
        return value.item()
    return value


def write_results(result: RunResult, out_dir: Path) -> Path:
    """Writes ``out_dir/results.json`` (creating ``out_dir``) and returns its path.

    The file is replaced atomically: an interrupted write leaves the previous
    file, or none, never half a file.
    """
    path = Path(out_dir) / "results.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(results_dict(result), indent=2, ensure_ascii=False) + "\n"
    with atomic_text_file(path) as stream:
        stream.write(text)
    return path


# -- the summary table ---------------------------------------------------------------


_Row = tuple[str, str | list[str], str]
"""``(label, value, note)``; a list value is comma-joined and wrapped under its column."""


def summary_table(result: RunResult) -> str:
    """A plain-text summary of ``result`` for a terminal, one figure per line."""
    items = plural(result.item_name)
    completed = result.status is RunStatus.COMPLETED
    status = "completed" if completed else _STATUS_WORDS.get(result.status, str(result.status))
    rows: list[_Row] = []
    if result.error:
        rows.append(("error", result.error, ""))
    wall = f"(wall {result.wall_time:,.1f} s)"
    if result.makespan is not None:
        rows.append(("makespan", f"{result.makespan:,.1f} s simulated", wall))
    else:
        rows.append(("makespan", f"not reached (ran {result.sim_time:,.1f} s simulated)", wall))
    if result.kind == "items":
        rows += _item_rows(result)
    else:
        rows += _objective_rows(result)
    if result.delivery_times:
        rows.append((f"{items} {result.verb} by", _delivered_parts(result), ""))
    for name, measured in result.metrics.items():
        rows.append((name.replace("_", " "), _measure_parts(result, name, measured), ""))
    distance = statistics(list(result.distance.values()))
    distance_text = _stats_text(distance, ("mean", "max"), _decimal)
    if distance["count"]:
        distance_text += f"  total {math.fsum(result.distance.values()):,.1f}"
    rows.append(("distance per robot", distance_text, ""))
    rows.append(("messages internal", _counts_parts(result.messages_internal, total=True), ""))
    rows.append(("messages external", _counts_parts(result.messages_external, total=True), ""))
    rows.append(("messages dropped", _counts_parts(result.protocol_errors, total=False), ""))
    if result.fail_on_drops is not None:
        rows.append(_fail_on_drops_row(result))
    if result.unanswered:
        rows.append(
            (
                "unanswered requests",
                _counts_parts(result.unanswered, total=False),
                "(get_intra_msg_reply returned None, and no reply followed)",
            )
        )
    if result.faults is not None:
        rows.append(("faults", _faults_parts(result.faults), ""))
    if result.groups:
        sizes = [f"{label} {len(ids):,}" for label, ids in result.groups.items()]
        rows.append(("robots", sizes, ""))
    for key, value in result.extra.items():
        label, note = _RUNTIME_EXTRAS.get(key, (str(key).replace("_", " "), ""))
        rows.append((label, _extra_text(value), note))
    header = f"{result.app} — {result.scenario}, seed {result.seed}: {status}"
    return "\n".join([header, *_render(rows)])


def _item_rows(result: RunResult) -> list[_Row]:
    """An item mission's rows: delivered, travel time and hand-overs per item."""
    item, items = result.item_name, plural(result.item_name)
    return [
        (
            f"{items} delivered",
            f"{result.delivered:,} of {result.target:,}",
            f"(created {result.created:,}, exchanges {result.exchanges:,})",
        ),
        (
            f"{item} travel time",
            _stats_text(
                statistics(result.travel_times), ("mean", "median", "p95"), _decimal, unit=" s"
            ),
            "",
        ),
        (
            f"hand-overs per {item}",
            _stats_text(
                statistics(result.handovers_per_item), ("mean", "median", "max"), _count_like
            ),
            "",
        ),
    ]


def _objective_rows(result: RunResult) -> list[_Row]:
    """A mission of its own: how many were done, then each of its samples' statistics."""
    items = plural(result.item_name)
    rows: list[_Row] = [
        (f"{items} {result.verb}", f"{result.delivered:,} of {result.target:,}", "")
    ]
    for name, values in result.samples.items():
        stats = statistics(values)
        rows.append(
            (name.replace("_", " "), _stats_text(stats, ("mean", "median", "max"), _decimal), "")
        )
    return rows


def _fail_on_drops_row(result: RunResult) -> _Row:
    """What ``--fail-on-drops`` asked, and whether the run's drops failed it."""
    reasons = ", ".join(result.fail_on_drops or ()) or "any reason"
    if not result.failing_drops:
        return ("fail on drops", reasons, "(none dropped: passed)")
    total = sum(result.failing_drops.values())
    return ("fail on drops", reasons, f"({total:,} dropped: the run failed)")


def _render(rows: Sequence[_Row]) -> list[str]:
    # the value column starts after the longest label, as in the thesis-style example
    width = max(_LABEL_WIDTH, *(len(label) + 1 for label, _, _ in rows))
    lines = []
    for label, value, note in rows:
        if isinstance(value, list):
            wrapped = _wrap(value, _LINE_WIDTH - width)
            if note:  # after the last part, or on a line of its own
                fits = len(wrapped[-1]) + 2 + len(note) <= _LINE_WIDTH - width
                wrapped = [*wrapped[:-1], f"{wrapped[-1]}  {note}"] if fits else [*wrapped, note]
            lines.append(f"{label:<{width}}{wrapped[0]}".rstrip())
            lines.extend(" " * width + line for line in wrapped[1:])
        elif note:
            lines.append(f"{label:<{width}}{value:<{_VALUE_WIDTH - 1}} {note}")
        else:
            lines.append(f"{label:<{width}}{value}".rstrip())
    return lines


def _wrap(parts: Sequence[str], width: int) -> list[str]:
    """``parts`` joined by ``", "`` into lines of at most ``width`` (unless one part is longer)."""
    lines: list[str] = []
    current = ""
    for k, part in enumerate(parts):
        piece = part + ("," if k < len(parts) - 1 else "")
        if current and len(current) + 1 + len(piece) > width:
            lines.append(current)
            current = piece
        else:
            current = f"{current} {piece}" if current else piece
    lines.append(current)
    return lines


def plural(noun: str) -> str:
    if noun.endswith(("s", "x", "z", "ch", "sh")):
        return noun + "es"
    if len(noun) > 1 and noun.endswith("y") and noun[-2] not in "aeiou":
        return noun[:-1] + "ies"
    return noun + "s"


def _decimal(value: float) -> str:
    return f"{value:,.1f}"


def _count_like(value: float) -> str:
    """Counts and their medians: ``3`` rather than ``3.0``, but ``2.5`` and ``2.9`` kept."""
    return f"{int(value):,}" if float(value).is_integer() else f"{value:,.1f}"


def _stats_text(
    stats: Mapping[str, float | None],
    keys: Sequence[str],
    fmt: Callable[[float], str],
    *,
    unit: str = "",
) -> str:
    if not stats["count"]:
        return "n/a (no values)"
    return "  ".join(f"{key} {fmt(cast(float, stats[key]))}" for key in keys) + unit


def _counts_parts(counts: Mapping[str, int], *, total: bool) -> str | list[str]:
    """``name n`` per entry, most frequent first (what a reader looks for), or ``none``."""
    if not counts:
        return "none"
    ordered = sorted(counts.items(), key=lambda pair: (-pair[1], pair[0]))
    parts = [f"{name} {n:,}" for name, n in ordered]
    if total:
        parts[-1] += f" (total {sum(counts.values()):,})"
    return parts


def _faults_parts(faults: Mapping[str, int]) -> list[str]:
    """``1,234 sent``, ``12 lost``, ... in the order the fault injector counts them."""
    return [f"{n:,} {name.replace('_', ' ')}" for name, n in faults.items()]


def _quarters(end: float) -> list[float]:
    return [end * k / 4 for k in range(1, 5)]


def _delivered_parts(result: RunResult) -> list[str]:
    """Items delivered by each quarter of the run: ``7.0 s: 2``, ..., ``27.9 s: 20``."""
    times = result.delivery_times
    return [f"{at:,.1f} s: {sum(t <= at for t in times):,}" for at in _quarters(result.sim_time)]


def _measure_parts(result: RunResult, name: str, value: float) -> list[str]:
    """A measure: its last third, its mean per quarter of the run, and by exchange count."""
    parts = [f"last third {value:.2f}"]
    series = result.series.get(name, {})
    times, values = series.get("t", []), series.get("value", [])
    ends = _quarters(result.sim_time)
    quarters = []
    for start, end in zip([0.0, *ends[:-1]], ends, strict=True):
        inside = [v for t, v in zip(times, values, strict=True) if start <= t <= end]
        quarters.append(f"{math.fsum(inside) / len(inside):.2f}" if inside else "-")
    parts.append("by quarter " + " ".join(quarters))
    by_exchange = result.by_exchange.get(name, {})
    counts, values = by_exchange.get("count", []), by_exchange.get("value", [])
    if counts:
        picks = sorted({round(k * (len(counts) - 1) / 3) for k in range(4)})
        parts.append(
            "after exchange " + " ".join(f"{counts[k]:,.0f}: {values[k]:.2f}" for k in picks)
        )
    return parts


_RUNTIME_EXTRAS: Final = {
    "behind_s": ("fell behind", "simulated s at most (the latest a sample came after its instant)"),
}
"""Extras the runtime adds, by key: their row's label and what the value means."""


def _extra_text(value: object) -> str:
    """An extra's value as the table shows it; never fails, whatever it is.

    ``RunResult.extra`` refuses what is not a number, a str or a bool, but a
    result may be made otherwise (read back, built by hand): such a value is shown
    as ``str()`` shows it.
    """
    if isinstance(value, bool | str):
        return str(value)
    if isinstance(value, numbers.Integral):
        return f"{int(value):,}"
    if isinstance(value, numbers.Real):
        return f"{float(value):.6g}"
    return str(value)
