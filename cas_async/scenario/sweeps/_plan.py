"""What a sweep will run: its axes (``--vary``), its grid of points, every run's overrides.

``--vary strategy.name=time,solo`` is one :class:`SweepAxis`; :func:`plan_sweep`
makes the cartesian product of the axes (in the order given) and loads every
point's scenario once, so that a wrong key or value is reported, naming the
point, before any run starts. Each run's overrides are, in order: the sweep's
defaults (virtual time, memory transport), the user's ``--set`` texts, the
point's ``key=value`` texts, then ``run.seed=S``. The plan keeps each point's
scenario data as it loaded it: a run is sent to a worker as that data
(:meth:`SweepPlan.run_data`), never as a path to read again.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from .._spec._config import ScenarioError, show
from .._spec._loader import apply_overrides, load_scenario, parse_override

__all__ = ["MAX_RUNS", "SWEEP_DEFAULTS", "SweepAxis", "SweepPlan", "parse_vary", "plan_sweep"]

SWEEP_DEFAULTS: Final = ("run.virtual=true", 'run.transport="memory"')
"""Overrides every run starts from; ``--set`` may change them (``run.virtual=false``
runs on scaled real time: allowed, but each run then takes wall time)."""
MAX_RUNS: Final = 100_000
"""A sweep of more runs than this is refused: it is a typo more often than a plan."""
_SEED_KEY: Final = "run.seed"
_SEED_OWN: Final = f"{_SEED_KEY} is the sweep's own: give the number of seeds with --seeds"
_SHOWN_POINTS: Final = 3


@dataclass(frozen=True, slots=True)
class SweepAxis:
    """One varied key and its values, as ``--vary KEY=a,b,c`` gives them.

    Attributes:
        key: the dotted scenario key.
        texts: each value as written, an override's right-hand side.
        values: each value as read: a TOML value, or the bare text when it is not one.
        labels: each value for people: strings as they are, the rest as TOML
            (``0.5``, ``true``); derived from ``values``.
    """

    key: str
    texts: tuple[str, ...]
    values: tuple[Any, ...]
    labels: tuple[str, ...] = dataclasses.field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        labels = tuple(value if isinstance(value, str) else show(value) for value in self.values)
        object.__setattr__(self, "labels", labels)  # frozen: set once, here


def parse_vary(text: str) -> SweepAxis:
    """Reads ``"KEY=a,b,c"`` into a :class:`SweepAxis`.

    Values are split at the commas outside brackets, braces and quotes (so
    ``[1, 2],[3, 4]`` is two arrays), and each is read as ``--set`` reads one
    (see :func:`~cas_async.scenario.parse_override`): ``0.5`` is a float and
    ``time`` the string ``"time"``.

    Raises:
        ScenarioError: on key ``--vary``: no ``=`` or an empty key, an empty
            value, a value listed twice, two values that read the same in
            ``runs.csv`` (``0.5`` and ``"0.5"``), or the key ``run.seed`` (the
            sweep's seeds are ``--seeds``).
    """
    key, equals, rest = text.partition("=")
    try:
        key, _ = parse_override(f"{key}=0")
    except ScenarioError:
        key = ""
    if not equals or not key:
        raise _vary_error(
            f"expected KEY=VALUE,VALUE,... such as strategy.name=time,solo, got {text!r}"
        )
    if key == _SEED_KEY:
        raise _vary_error(_SEED_OWN)
    if not rest.strip():
        raise _vary_error(f"{key}: no values: give them as {key}=A,B,...")
    texts = tuple(_split_values(rest))
    values: list[Any] = []
    seen: set[str] = set()
    for item in texts:
        if not item:
            raise _vary_error(f"{key}: empty value in {rest!r}")
        value = parse_override(f"{key}={item}")[1]
        if (shown := show(value)) in seen:
            raise _vary_error(f"{key}: value {item} is listed twice")
        seen.add(shown)
        values.append(value)
    axis = SweepAxis(key, texts, tuple(values))
    # A row of runs.csv names its point by the labels: they must tell the values apart.
    for k, label in enumerate(axis.labels):
        if label in axis.labels[:k]:
            first = texts[axis.labels.index(label)]
            raise _vary_error(
                f"{key}: values {first} and {texts[k]} both read {label} in runs.csv: keep one"
            )
    return axis


def _vary_error(message: str) -> ScenarioError:
    return ScenarioError([("--vary", message)])


def _split_values(text: str) -> list[str]:
    """``text`` split at the commas that are not inside ``[]``, ``{}`` or a quoted string."""
    items: list[str] = []
    depth, quote, escaped, start = 0, "", False, 0
    for index, char in enumerate(text):
        if quote:
            if escaped:
                escaped = False
            elif char == "\\" and quote == '"':
                escaped = True
            elif char == quote:
                quote = ""
        elif char in "\"'":
            quote = char
        elif char in "[{":
            depth += 1
        elif char in "]}":
            depth = max(0, depth - 1)
        elif char == "," and not depth:
            items.append(text[start:index].strip())
            start = index + 1
    items.append(text[start:].strip())
    return items


@dataclass(frozen=True, slots=True)
class SweepPlan:
    """A valid sweep: a scenario, its grid and its seeds. Made by :func:`plan_sweep`.

    Attributes:
        path: the scenario file, as given.
        seeds: runs per point, with seeds ``1..seeds``.
        axes: the varied keys, in the order given.
        overrides: the user's ``--set`` texts.
        points: the grid: per point, the index of its value on each axis, in the
            order of the cartesian product (the last axis varies fastest).
        real_time: some point runs on scaled real time (``run.virtual=false``).
        contents: per point, its scenario data as :func:`plan_sweep` loaded it (the
            file and what it extends, every override applied but ``run.seed``);
            empty in a plan made by hand (see :meth:`point_data`).
    """

    path: Path
    seeds: int
    axes: tuple[SweepAxis, ...]
    overrides: tuple[str, ...]
    points: tuple[tuple[int, ...], ...]
    real_time: bool = False
    contents: tuple[Mapping[str, Any], ...] = dataclasses.field(
        default=(), repr=False, compare=False
    )

    @property
    def runs(self) -> int:
        """How many runs the sweep makes: points times seeds."""
        return len(self.points) * self.seeds

    def run_overrides(self, point: int, seed: int) -> list[str]:
        """The overrides of the run of ``point`` (an index into :attr:`points`) and ``seed``."""
        varied = [
            f"{axis.key}={axis.texts[k]}"
            for axis, k in zip(self.axes, self.points[point], strict=True)
        ]
        return [*SWEEP_DEFAULTS, *self.overrides, *varied, f"{_SEED_KEY}={seed}"]

    def point_data(self, point: int) -> dict[str, Any]:
        """The scenario data of ``point``, without ``run.seed``: what its runs share.

        A copy of :attr:`contents`, or the file read again when the plan has none.
        """
        if self.contents:
            return apply_overrides(self.contents[point], ())
        return _without_seed(load_scenario(self.path, self.run_overrides(point, 1)).data)

    def run_data(self, point: int, seed: int) -> dict[str, Any]:
        """The scenario data of the run of ``point`` and ``seed``.

        What a worker runs (:func:`~cas_async.scenario.scenario_from_data`), so that
        it needs neither the file nor what it extends: the same data
        :func:`~cas_async.scenario.load_scenario` gives with :meth:`run_overrides`.
        """
        return apply_overrides(self.point_data(point), [(_SEED_KEY, seed)])

    def labels(self, point: int) -> tuple[str, ...]:
        """The values of ``point``, one per axis, for people."""
        return tuple(axis.labels[k] for axis, k in zip(self.axes, self.points[point], strict=True))

    def describe(self, point: int) -> str:
        """``"strategy.name=time handover_time=0.5"``: the point's keys and values."""
        pairs = zip(self.axes, self.labels(point), strict=True)
        return " ".join(f"{axis.key}={label}" for axis, label in pairs)


def plan_sweep(
    path: str | os.PathLike[str],
    *,
    seeds: int,
    vary: Sequence[str | SweepAxis] = (),
    overrides: Sequence[str] = (),
) -> SweepPlan:
    """Checks a sweep and returns its plan; nothing runs.

    Every point's scenario is loaded once (with seed 1): every problem of every
    point is reported, each naming the points where it occurs.

    Args:
        path: the scenario file.
        seeds: runs per point (seeds ``1..seeds``), at least 1.
        vary: the axes, as ``--vary`` texts (see :func:`parse_vary`) or parsed.
        overrides: ``--set`` texts, applied after the sweep's defaults and before
            the varied values; ``run.seed`` is refused.

    Raises:
        ScenarioError: an axis, override or count is not valid (key ``--vary``,
            ``--set`` or ``--seeds``), the sweep makes more than :data:`MAX_RUNS`
            runs (key ``grid``), or a point's scenario is not valid (naming the
            file and the points).
    """
    if seeds < 1:
        raise ScenarioError([("--seeds", f"expected at least 1 seed, got {seeds}")])
    axes = tuple(parse_vary(axis) if isinstance(axis, str) else axis for axis in vary)
    keys = [axis.key for axis in axes]
    if twice := sorted({key for key in keys if keys.count(key) > 1}):
        raise _vary_error(f"{', '.join(twice)} is varied twice: give all its values in one --vary")
    if any(parse_override(text)[0] == _SEED_KEY for text in overrides):
        raise ScenarioError([("--set", _SEED_OWN)])
    sizes = [len(axis.values) for axis in axes]
    if (runs := math.prod(sizes) * seeds) > MAX_RUNS:
        grid = " x ".join(f"{size} values" for size in sizes)
        size = f"{grid} x {seeds:,} seeds" if sizes else f"{seeds:,} seeds"
        raise ScenarioError(
            [("grid", f"{size} = {runs:,} runs, more than a sweep makes ({MAX_RUNS:,} at most)")]
        )
    points = tuple(itertools.product(*(range(size) for size in sizes)))
    plan = SweepPlan(Path(path), seeds, axes, tuple(overrides), points)
    return _checked(plan)


def _checked(plan: SweepPlan) -> SweepPlan:
    """``plan`` once every point's scenario loaded; ``real_time`` filled in."""
    found: dict[tuple[str, str], list[str]] = {}  # problem -> the points that have it
    file = os.fspath(plan.path)
    real_time = False
    contents = []
    for point in range(len(plan.points)):
        try:
            scenario = load_scenario(plan.path, plan.run_overrides(point, 1))
        except ScenarioError as error:
            file = error.file or file
            for problem in error.problems:
                found.setdefault(problem, []).append(plan.describe(point))
            continue
        real_time = real_time or not scenario.run.virtual
        contents.append(_without_seed(scenario.data))
    if found:
        problems = [
            (key, message + _where(points, len(plan.points)) if plan.axes else message)
            for (key, message), points in found.items()
        ]
        raise ScenarioError(problems, file)
    return dataclasses.replace(plan, real_time=real_time, contents=tuple(contents))


def _without_seed(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` (changed in place) without ``run.seed``, which the plan's seeds set."""
    run = data.get("run")
    if isinstance(run, dict):
        run.pop("seed", None)
    return data


def _where(points: list[str], total: int) -> str:
    if len(points) == total > 1:
        return " (at every point of the grid)"
    shown = "; ".join(points[:_SHOWN_POINTS])
    more = len(points) - _SHOWN_POINTS
    return f" (at {shown}" + (f"; and {more} more points)" if more > 0 else ")")
