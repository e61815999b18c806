"""``sweep.json``: what a sweep is, written as it starts, so that ``--resume`` knows it again.

A run is known by the scenario's content, its point and its seed. The content is
the scenario's data after the sweep's defaults and ``--set`` (the file and what
it ``extends`` merged), not the file's bytes: comments, formatting, key order or
a moved file change nothing; any value that changes the runs does. The file
holds, besides the version of cas_async that began the sweep:

* ``scenario_data`` (and its ``scenario_sha256``): what every point shares, the
  data without ``run.seed`` and without the varied keys;
* ``vary`` and ``seeds``: the grid, each value as ``runs.csv`` shows it;
* ``points``: per point its values and the SHA-256 of its whole data.

:func:`check_resume` compares a plan with the file and refuses, saying what
changed, when they are not the same sweep. A change in the application's code
is not seen: the version is recorded, and a resumed sweep says when it differs.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, Final

from ... import __version__
from .._spec._config import ScenarioError, show
from ..output._atomic_files import atomic_text_file
from ._plan import SweepPlan

__all__ = ["MANIFEST", "check_resume", "write_manifest"]

MANIFEST: Final = "sweep.json"
_FORMAT: Final = 1
_SHOWN: Final = 4
"""Changes named in a refusal; the rest are counted."""


def write_manifest(out: Path, plan: SweepPlan) -> Path:
    """Writes ``out/sweep.json`` for ``plan`` (whole or not at all); returns its path."""
    text = json.dumps(_manifest(plan), indent=2, ensure_ascii=False, default=str)
    path = out / MANIFEST
    with atomic_text_file(path) as stream:
        stream.write(text + "\n")
    return path


def check_resume(out: Path, plan: SweepPlan) -> str | None:
    """Checks that ``out`` holds the sweep of ``plan``; returns a note for people, or ``None``.

    Raises:
        ScenarioError: on key ``--resume``: ``out`` holds no sweep, or another
            one (the message says what changed).
    """
    path = out / MANIFEST
    try:
        was = json.loads(path.read_text("utf-8"))
    except FileNotFoundError:
        raise _refused(
            f"nothing to resume in {out}/: no {MANIFEST} (a sweep writes it as it starts)"
        ) from None
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise _refused(f"cannot read {path}: {error}") from None
    if not isinstance(was, dict) or was.get("format") != _FORMAT:
        raise _refused(f"{path} is not a sweep's {MANIFEST} (format {_FORMAT})")
    now = _manifest(plan)
    changes = _changes(was, now)
    if changes:
        raise _refused(f"{out}/ holds another sweep: {'; '.join(changes)}")
    began = was.get("cas_async")
    if began != now["cas_async"]:
        return (
            f"note: the sweep in {out}/ was begun with cas_async {began}, this is "
            f"{now['cas_async']}: its finished runs are kept as they are"
        )
    return None


def _refused(message: str) -> ScenarioError:
    return ScenarioError([("--resume", message)])


def _manifest(plan: SweepPlan) -> dict[str, Any]:
    keys = [axis.key for axis in plan.axes]
    shared = _canonical(_without(plan.point_data(0), keys))
    return {
        "format": _FORMAT,
        "cas_async": __version__,
        "scenario": str(plan.path),
        "scenario_sha256": _sha256(shared),
        "scenario_data": shared,
        "overrides": list(plan.overrides),
        "vary": [{"key": axis.key, "values": list(axis.labels)} for axis in plan.axes],
        "seeds": plan.seeds,
        "runs": plan.runs,
        "points": [
            {"values": list(plan.labels(point)), "sha256": _sha256(plan.point_data(point))}
            for point in range(len(plan.points))
        ],
    }


def _changes(was: Mapping[str, Any], now: Mapping[str, Any]) -> list[str]:
    """What differs between two manifests, for people; empty when it is the same sweep."""
    changes = []
    old_axes = _axes(was)
    new_axes = _axes(now)
    varied = [*old_axes, *(key for key in new_axes if key not in old_axes)]
    scenario = _differences(
        _without(_mapping(was.get("scenario_data")), varied),
        _without(now["scenario_data"], varied),
    )
    if scenario:
        changes.append(f"the scenario changed ({scenario})")
    grid = []
    for key in varied:
        if key not in new_axes:
            grid.append(f"--vary {key} left out")
        elif key not in old_axes:
            grid.append(f"--vary {key}={','.join(new_axes[key])} added")
        elif old_axes[key] != new_axes[key]:
            grid.append(
                f"--vary {key} was {','.join(old_axes[key])}, now {','.join(new_axes[key])}"
            )
    if not grid and list(old_axes) != list(new_axes):
        grid.append(f"the --vary order was {', '.join(old_axes)}, now {', '.join(new_axes)}")
    if was.get("seeds") != now["seeds"]:
        grid.append(f"--seeds was {was.get('seeds')}, now {now['seeds']}")
    if grid:
        changes.append(f"the grid changed ({'; '.join(grid)})")
    if not changes and _hashes(was) != _hashes(now):  # values that read the same but differ
        changes.append('the points\' values changed (as TOML: 1 is not 1.0, true is not "true")')
    return changes


def _axes(manifest: Mapping[str, Any]) -> dict[str, list[str]]:
    axes = manifest.get("vary")
    if not isinstance(axes, list):
        return {}
    return {
        str(axis.get("key")): [str(value) for value in axis.get("values", [])]
        for axis in axes
        if isinstance(axis, dict)
    }


def _hashes(manifest: Mapping[str, Any]) -> list[Any]:
    points = manifest.get("points")
    if not isinstance(points, list):
        return []
    return [point.get("sha256") for point in points if isinstance(point, dict)]


def _differences(was: Mapping[str, Any], now: Mapping[str, Any]) -> str:
    """``"mission.buckets was 3, now 4; robots.count added"``: the first few, then a count."""
    old, new = dict(_flat(was)), dict(_flat(now))
    found = []
    for key in [*old, *(key for key in new if key not in old)]:
        if key not in new:
            found.append(f"{key} removed")
        elif key not in old:
            found.append(f"{key} = {show(new[key])} added")
        elif old[key] != new[key]:
            found.append(f"{key} was {show(old[key])}, now {show(new[key])}")
    more = len(found) - _SHOWN
    return "; ".join(found[:_SHOWN]) + (f"; and {more} more" if more > 0 else "")


def _flat(data: Mapping[str, Any], prefix: str = "") -> Iterator[tuple[str, Any]]:
    for key, value in data.items():
        if isinstance(value, dict) and value:
            yield from _flat(value, f"{prefix}{key}.")
        else:
            yield f"{prefix}{key}", value


def _without(data: Mapping[str, Any], keys: list[str]) -> dict[str, Any]:
    """A copy of ``data`` without the dotted ``keys``, nor the tables they leave empty."""
    copy: dict[str, Any] = json.loads(_text(data))
    for key in keys:
        _drop(copy, key.split("."))
    return copy


def _drop(table: dict[str, Any], path: list[str]) -> None:
    first, *rest = path
    if rest and isinstance(table.get(first), dict):
        _drop(table[first], rest)
        if not table[first]:
            del table[first]
    elif not rest:
        table.pop(first, None)


def _mapping(value: Any) -> Mapping[str, Any]:
    return value if isinstance(value, dict) else {}


def _canonical(data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` as JSON reads it back: TOML's dates and times become text."""
    return json.loads(_text(data))  # type: ignore[no-any-return]


def _sha256(data: Mapping[str, Any]) -> str:
    return hashlib.sha256(_text(data).encode("utf-8")).hexdigest()


def _text(data: Mapping[str, Any]) -> str:
    return json.dumps(data, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=str)
