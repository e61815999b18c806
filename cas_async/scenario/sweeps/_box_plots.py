"""A sweep's box plots: per metric, a box per point of the grid, over the completed runs.

As in :mod:`._plots`, matplotlib (a base dependency) is imported only inside
:func:`write_box_plots`, and figures are drawn with ``matplotlib.figure.Figure`` on
an Agg canvas, never through pyplot.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np

from ..output._atomic_files import atomic_binary_file
from ._outcome import SweepOutcome

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["plot_file_name", "write_box_plots"]

_DPI: Final = 100
_JITTER: Final = 0.12
"""Half the width, in boxes, over which a box's own values are spread as dots."""
_ROTATE_FROM: Final = 8
"""From this many points on, the labels under the boxes are slanted."""


def plot_file_name(metric: str) -> str:
    """``box_<metric>.png``; anything but letters, digits, ``.``, ``-`` and ``_`` becomes ``_``."""
    return f"box_{re.sub(r'[^A-Za-z0-9._-]', '_', metric)}.png"


def write_box_plots(outcome: SweepOutcome, out_dir: Path) -> list[Path]:
    """Writes ``box_<metric>.png`` to ``out_dir`` for every metric a completed run has.

    Each figure has a box per point of the grid, labelled with its values, and
    the point's values as dots over it; a point without values keeps its place,
    marked "no completed run". Two metrics whose file names would clash get one
    figure, the first's.

    Returns:
        The paths written, in the order of :attr:`SweepOutcome.metrics`.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    groups = outcome.by_point()
    paths: list[Path] = []
    for metric in outcome.metrics:
        path = out_dir / plot_file_name(metric)
        values = [
            [
                run.scalars[metric]
                for run in runs
                if run.completed and metric in run.scalars and math.isfinite(run.scalars[metric])
            ]
            for runs in groups
        ]
        if path not in paths and any(values):
            paths.append(_save(_box_figure(outcome, metric, values), path))
    return paths


def _box_figure(outcome: SweepOutcome, metric: str, values: list[list[float]]) -> Figure:
    from matplotlib.figure import Figure

    plan = outcome.plan
    positions = range(1, len(values) + 1)
    labels = ["\n".join(plan.labels(point)) or plan.path.stem for point in range(len(values))]
    width = min(24.0, max(6.0, 1.5 + 0.9 * len(values)))
    figure = Figure(figsize=(width, 4.8), dpi=_DPI)
    axes = figure.add_subplot()
    filled = [k for k, box in enumerate(values) if box]
    axes.boxplot(
        [values[k] for k in filled],
        positions=[positions[k] for k in filled],
        widths=0.6,
        showmeans=True,
        showfliers=False,  # every value is drawn as a dot
    )
    for k, box in enumerate(values):
        if box:
            spread = np.linspace(-_JITTER, _JITTER, len(box)) if len(box) > 1 else np.zeros(1)
            axes.scatter(positions[k] + spread, box, s=10, color="C0", alpha=0.5, zorder=3)
        else:
            at = (positions[k], 0.03)  # x in data, y in axes fraction
            axes.annotate(
                "no completed run",
                at,
                xycoords=("data", "axes fraction"),
                ha="center",
                fontsize=8,
                color="grey",
            )
    rotate = len(values) >= _ROTATE_FROM
    axes.set_xticks(
        positions, labels, rotation=30 if rotate else 0, ha="right" if rotate else "center"
    )
    axes.set_xlim(0.4, len(values) + 0.6)
    axes.set_xlabel(" / ".join(axis.key for axis in plan.axes))
    axes.set_ylabel(metric)
    axes.grid(axis="y", alpha=0.3)
    seeds = "seed 1" if plan.seeds == 1 else f"seeds 1-{plan.seeds}"
    title = f"{metric}\n{plan.path.name}, {seeds}: completed runs (triangle: mean)"
    axes.set_title(title, fontsize=10)
    # fixed margins, as in ._plots: a layout engine measures every label first
    bottom = 0.25 if rotate else 0.08 + 0.04 * max(1, len(plan.axes))
    figure.subplots_adjust(left=0.1, right=0.97, top=0.87, bottom=bottom)
    return figure


def _save(figure: Figure, path: Path) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(figure)
    with atomic_binary_file(path) as stream:  # an interrupted figure leaves no partial file
        figure.savefig(stream, dpi=_DPI, format="png")
    return path
