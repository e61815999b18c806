"""PNG figures of a run's :class:`~cas_async.scenario.output.Trace`, like the thesis's Figs. 33-36.

matplotlib is imported only inside :func:`write_plots`, so importing cas_async never
pays for it (or needs it). Figures are drawn with ``matplotlib.figure.Figure`` on an
Agg canvas, never through pyplot: no global state, no window, safe in any process.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np
import numpy.typing as npt

from ._atomic_files import atomic_binary_file
from ._plot_labels import id_labels
from ._trace import Trace

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["write_plots"]

_DPI: Final = 100
_PANELS: Final = 6
_MARKERS: Final = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">")
_NAMED: Final = 300
"""Robots up to which the snapshots and trajectories write each robot's id."""
_UNLABELLED: Final = ""
"""The row of a run without groups: its robots get no legend entry (not ``"other"``)."""
_MARGIN: Final = 0.03
"""Fraction of the larger world side left around the world, so robots on its edge show."""


def write_plots(
    trace: Trace,
    groups: dict[str, list[int]],
    world: tuple[float, float],
    out_dir: Path,
    *,
    title: str,
    exchanges_traced: bool = True,
    snapshot_exchanges: Sequence[int] = (),
    delivery_times: Sequence[float] = (),
    series: Mapping[str, Mapping[str, Sequence[float]]] | None = None,
    item_name: str = "item",
    verb: str = "delivered",
) -> list[Path]:
    """Writes the figures of a run to ``out_dir``: five, four without exchanges.

    ``initial_positions.png``, ``snapshots_by_exchange.png``, ``snapshots_by_time.png``,
    ``trajectories.png`` and ``over_time.png``:

    * initial positions: the first regular sample, robot ids annotated.
    * by exchange: six snapshots: at the ``snapshot_exchanges`` counts the run
      reached, at the last snapshot, and at counts spread evenly between to fill
      the six (fewer if fewer exist). A run without exchanges (an objective that
      reports none) gets no such figure; with ``trace_exchanges`` off, it says so.
    * by time: six regular samples at times spread evenly from the first to the
      last (a note if there are none).
    * trajectories: every robot's path through the regular samples, from a hollow
      marker (its start) to a filled one (its end), ids at the end.
    * over time: items delivered and exchanges made over time, and below, each of
      ``series`` (the application's measures) over time.

    In the snapshots, robot ids are written next to each robot (robots standing
    together share one label: ``"1,3"``) and a robot that carries an item is
    circled in black.

    Args:
        trace: the run's positions.
        groups: robot ids by label, in legend order; each group gets its own colour
            and marker. Robots of the trace in no group are drawn as ``"other"``;
            ids not in the trace are ignored. No groups at all: one colour, no legend.
        world: ``(width, height)`` of the area, with its corner at ``(0, 0)``.
        out_dir: where to write (created if missing).
        title: shown above every figure (e.g. the app's name and the seed).
        exchanges_traced: whether the run recorded exchange snapshots (``[run]
            trace_exchanges``); when not, the exchange figure says so rather than
            "no exchanges recorded".
        snapshot_exchanges: exchange counts to show, where reached (``Mission``).
        delivery_times: the instant of each delivery (``RunResult.delivery_times``).
        series: measures over time, ``{name: {"t": [...], "value": [...]}}``
            (``RunResult.series``).
        item_name: what the items are called, singular.
        verb: what is done to them (``RunResult.verb``: ``"delivered"``).

    Returns:
        The paths written, in the order above.
    """
    from matplotlib.figure import Figure

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = _group_rows(trace, groups)
    paths = []

    figure = Figure(figsize=(8, 7), dpi=_DPI)
    figure.suptitle(f"{title}: initial positions")
    # fixed margins rather than a layout engine: measuring every tick label for
    # constrained layout costs more than drawing the figure
    figure.subplots_adjust(left=0.08, right=0.8, bottom=0.08, top=0.9)
    axes = figure.add_subplot()
    if len(trace.times):
        _scatter(axes, trace.positions[0], rows, world, size=22)
        if len(trace.ids) <= _NAMED:
            for text, at in id_labels(trace.ids, trace.positions[0], world):
                axes.annotate(text, at, xytext=(3, 3), textcoords="offset points", fontsize=6)
        if _labelled(rows):
            axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        axes.set_title(f"t = {trace.times[0]:.1f} s", fontsize=10)
    else:
        _note(axes, "no samples recorded")
    paths.append(_save(figure, out_dir / "initial_positions.png"))

    counts = trace.exchange_counts
    picks = _exchange_picks(counts, snapshot_exchanges, _PANELS)
    panels = [
        (
            f"after exchange {counts[k]} (t = {trace.exchange_times[k]:.1f} s)",
            trace.exchange_positions[k],
            trace.exchange_carrying[k],
        )
        for k in picks
    ]
    if panels or not exchanges_traced:  # no figure at all for a run without exchanges
        figure = _panels(f"{title}: snapshots by exchange", panels, rows, world, trace.ids)
        if not panels:
            _note(
                figure.add_subplot(),
                "exchange snapshots switched off\n([run] trace_exchanges = false)",
            )
        paths.append(_save(figure, out_dir / "snapshots_by_exchange.png"))

    times = trace.times
    picks = _at_times(times, _PANELS)
    panels = [(f"t = {times[k]:.1f} s", trace.positions[k], trace.carrying[k]) for k in picks]
    figure = _panels(f"{title}: snapshots by time", panels, rows, world, trace.ids)
    if not panels:
        _note(figure.add_subplot(), "no samples recorded")
    paths.append(_save(figure, out_dir / "snapshots_by_time.png"))

    paths.append(_save(_trajectories(trace, rows, world, title), out_dir / "trajectories.png"))
    figure = _over_time(trace, delivery_times, series or {}, title, f"{item_name}s {verb}")
    paths.append(_save(figure, out_dir / "over_time.png"))
    return paths


def _exchange_picks(counts: npt.NDArray[np.int64], wanted: Sequence[int], panels: int) -> list[int]:
    """Snapshot indices: the wanted counts reached, the last, then evenly spread ones."""
    if not len(counts):
        return []
    chosen: set[int] = set()
    for count in sorted(set(wanted)):
        k = int(np.searchsorted(counts, count, side="right")) - 1
        if count <= counts[-1] and k >= 0 and len(chosen) < panels - 1:
            chosen.add(k)
    chosen.add(len(counts) - 1)
    # fill the gaps: each time, the spread index farthest from those chosen
    spare = set(_spread(len(counts), panels * 4)) - chosen
    while spare and len(chosen) < panels:
        best = max(sorted(spare), key=lambda k: min(abs(k - c) for c in chosen))
        chosen.add(best)
        spare.discard(best)
    return sorted(chosen)


def _trajectories(
    trace: Trace, rows: list[tuple[str, list[int]]], world: tuple[float, float], title: str
) -> Figure:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(9, 8), dpi=_DPI)
    figure.suptitle(f"{title}: trajectories")
    figure.subplots_adjust(left=0.08, right=0.8, bottom=0.08, top=0.9)
    axes = figure.add_subplot()
    positions = trace.positions
    if len(positions) < 2:
        _note(axes, "fewer than two samples recorded")
        return figure
    from matplotlib.collections import LineCollection

    moved = np.flatnonzero(np.any(positions != positions[0], axis=(0, 2)))
    colours = [f"C{n % 10}" for n in range(len(moved))]
    paths = np.swapaxes(positions[:, moved, :], 0, 1)  # (robots, samples, 2)
    axes.add_collection(LineCollection(list(paths), colors=colours, linewidths=0.8, alpha=0.7))
    starts, ends = positions[0, moved], positions[-1, moved]
    axes.scatter(starts[:, 0], starts[:, 1], s=18, facecolors="none", edgecolors=colours)
    axes.scatter(ends[:, 0], ends[:, 1], s=18, color=colours)
    if len(moved) <= _NAMED:
        moved_ids = [trace.ids[k] for k in moved.tolist()]
        for text, at in id_labels(moved_ids, ends, world):
            axes.annotate(text, at, xytext=(3, 3), textcoords="offset points", fontsize=6)
    moving = set(moved.tolist())
    still = [(label, [k for k in members if k not in moving]) for label, members in rows]
    still = [(label, ks) for label, ks in still if ks]
    _scatter(axes, positions[-1], still, world, size=40)
    if _labelled(still):
        axes.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    axes.set_title(
        f"t = {trace.times[0]:.1f} to {trace.times[-1]:.1f} s; hollow: start, filled: end",
        fontsize=10,
    )
    return figure


def _over_time(
    trace: Trace,
    delivery_times: Sequence[float],
    series: Mapping[str, Mapping[str, Sequence[float]]],
    title: str,
    done: str,
) -> Figure:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(9, 7 if series else 4.5), dpi=_DPI)
    figure.suptitle(f"{title}: over time")
    grid = figure.subplots(2 if series else 1, 1, squeeze=False, sharex=True)
    axes = grid[0, 0]
    delivered = sorted(delivery_times)
    end = max([*trace.times.tolist(), *trace.exchange_times.tolist(), *delivered], default=0.0)
    axes.step([0.0, *delivered, end], [0, *range(1, len(delivered) + 1), len(delivered)],
              where="post", label=done)  # fmt: skip
    axes.set_ylabel(done)
    exchanges = trace.exchange_counts
    if len(exchanges):
        twin = axes.twinx()
        twin.step([0.0, *trace.exchange_times.tolist()], [0, *exchanges.tolist()],
                  where="post", color="C1", label="exchanges")  # fmt: skip
        twin.set_ylabel("exchanges", color="C1")
    axes.grid(True, linewidth=0.5, alpha=0.5)
    axes.legend(loc="upper left", fontsize=8)
    if series:
        below = grid[1, 0]
        for n, (name, values) in enumerate(series.items()):
            below.plot(values.get("t", []), values.get("value", []), color=f"C{n + 2}", label=name)
        below.set_xlabel("simulated time (s)")
        below.grid(True, linewidth=0.5, alpha=0.5)
        below.legend(loc="upper left", fontsize=8)
    else:
        axes.set_xlabel("simulated time (s)")
    return figure


def _group_rows(trace: Trace, groups: dict[str, list[int]]) -> list[tuple[str, list[int]]]:
    """``(label, trace rows)`` per non-empty group, robots in no group last as ``"other"``.

    Without groups at all, every robot is in one row that no legend shows.
    """
    row_of = {robot_id: k for k, robot_id in enumerate(trace.ids)}
    if not groups:
        return [(_UNLABELLED, list(row_of.values()))] if row_of else []
    placed: set[int] = set()
    rows = []
    for label, ids in groups.items():
        members = [row_of[i] for i in ids if i in row_of and i not in placed]
        placed.update(i for i in ids if i in row_of)
        if members:
            rows.append((label, members))
    others = [k for robot_id, k in row_of.items() if robot_id not in placed]
    if others:
        rows.append(("other", others))
    return rows


def _labelled(rows: Sequence[tuple[str, list[int]]]) -> bool:
    """Whether a legend has anything to show for ``rows``."""
    return any(label != _UNLABELLED for label, _ in rows)


def _spread(available: int, wanted: int) -> list[int]:
    """Up to ``wanted`` indices of ``range(available)``, evenly spread, first and last included."""
    if available <= wanted:
        return list(range(available))
    return sorted({round(k) for k in np.linspace(0, available - 1, wanted).tolist()})


def _at_times(times: npt.NDArray[np.float64], wanted: int) -> list[int]:
    """Indices of the last sample at or before each of ``wanted`` evenly spread instants."""
    if not len(times):
        return []
    instants = np.linspace(times[0], times[-1], wanted)
    indices = np.searchsorted(times, instants, side="right") - 1
    return sorted({max(0, int(k)) for k in indices.tolist()})


def _panels(
    title: str,
    panels: Sequence[tuple[str, npt.NDArray[np.float64], npt.NDArray[np.bool_]]],
    rows: list[tuple[str, list[int]]],
    world: tuple[float, float],
    ids: Sequence[int],
) -> Figure:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(15, 9.5), dpi=_DPI)
    figure.suptitle(title)
    if not panels:
        return figure
    figure.subplots_adjust(left=0.05, right=0.98, bottom=0.12, top=0.92, wspace=0.2, hspace=0.28)
    # one world in every panel: shared axes label only the outer ones, which also halves
    # the tick labels to lay out
    grid = figure.subplots(2, 3, squeeze=False, sharex=True, sharey=True)
    for axes, (panel_title, xy, carrying) in zip(grid.flat, panels, strict=False):
        _scatter(axes, xy, rows, world, size=10)
        _mark(axes, xy, carrying, ids, world)
        axes.set_title(panel_title, fontsize=10)
        axes.label_outer()
    for k in range(len(panels), _PANELS):
        grid.flat[k].set_axis_off()
        if k >= 3:  # the panel above is now its column's lowest: give it the x labels
            grid.flat[k - 3].tick_params(labelbottom=True)
            grid.flat[k - 3].set_xlabel("x")
    handles, labels = grid.flat[0].get_legend_handles_labels()  # groups, and "carrying"
    if handles:
        figure.legend(handles, labels, loc="lower center", ncols=min(len(handles), 6))
    return figure


def _scatter(
    axes: Axes,
    xy: npt.NDArray[np.float64],
    rows: list[tuple[str, list[int]]],
    world: tuple[float, float],
    *,
    size: float,
) -> None:
    for k, (label, members) in enumerate(rows):
        points = xy[members]
        axes.scatter(
            points[:, 0],
            points[:, 1],
            s=size,
            marker=_MARKERS[k % len(_MARKERS)],
            color=f"C{k % 10}",
            label=None if label == _UNLABELLED else label,
        )
    width, height = world
    margin = _MARGIN * max(width, height)
    axes.set_xlim(-margin, width + margin)
    axes.set_ylim(-margin, height + margin)
    axes.set_aspect("equal")
    axes.grid(True, linewidth=0.5, alpha=0.5)
    axes.set_xlabel("x")
    axes.set_ylabel("y")


def _mark(
    axes: Axes,
    xy: npt.NDArray[np.float64],
    carrying: npt.NDArray[np.bool_],
    ids: Sequence[int],
    world: tuple[float, float],
) -> None:
    """Circles the robots that carry an item and writes every robot's id beside it.

    Robots standing together share a label (see :func:`id_labels`). Ids only up to
    ``_NAMED`` robots: thousands of labels are unreadable, and slow to draw.
    """
    held = xy[carrying]
    if len(held):
        axes.scatter(held[:, 0], held[:, 1], s=45, facecolors="none", edgecolors="black",
                     linewidths=0.8, label="carrying")  # fmt: skip
    if len(ids) > _NAMED:
        return
    for text, at in id_labels(ids, xy, world):
        axes.annotate(text, at, xytext=(2, 2), textcoords="offset points", fontsize=5)


def _note(axes: Axes, text: str) -> None:
    axes.set_axis_off()
    axes.text(0.5, 0.5, text, ha="center", va="center", fontsize=14, transform=axes.transAxes)


def _save(figure: Figure, path: Path) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(figure)
    with atomic_binary_file(path) as stream:  # an interrupted figure leaves no partial file
        figure.savefig(stream, dpi=_DPI, format="png")
    return path
