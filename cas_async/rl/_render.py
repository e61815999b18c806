"""``render()``'s picture: the run's latest trace sample, as an RGB array.

The runner samples every robot's position every ``run.trace_interval`` simulated
seconds (and marks who carries an item); this draws the latest sample as the
run's figures draw their snapshots: one colour and marker per group, carriers
circled. matplotlib is imported here only, on an Agg canvas (no window, no pyplot).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Final

import numpy as np
import numpy.typing as npt

from ..scenario.output import Trace
from ..sim import Environment

__all__ = ["draw"]

_MARKERS: Final = ("o", "s", "^", "D", "v", "P", "X", "*")
_SIZE: Final = (7.0, 5.0)
"""Inches; at 100 dpi a 700 x 500 image."""
_DPI: Final = 100


def draw(
    trace: Trace,
    environment: Environment,
    groups: Mapping[str, Sequence[int]],
    world: tuple[float, float],
    title: str,
) -> npt.NDArray[np.uint8]:
    """The latest sample of ``trace`` (or the robots at time 0 before any), ``(h, w, 3)``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ids = list(trace.ids)
    if len(trace.times):
        t = float(trace.times[-1])
        xy = trace.positions[-1]
        carrying = trace.carrying[-1]
    else:  # not started: where the app put them
        t = 0.0
        positions = environment.positions_at(0.0).as_dict()
        xy = np.array([positions[robot] for robot in ids], dtype=np.float64).reshape(-1, 2)
        carrying = np.zeros(len(ids), dtype=np.bool_)
    figure = Figure(figsize=_SIZE, dpi=_DPI)
    canvas = FigureCanvasAgg(figure)
    figure.subplots_adjust(left=0.08, right=0.76, bottom=0.08, top=0.92)
    axes = figure.add_subplot()
    row = {robot: k for k, robot in enumerate(ids)}
    placed: set[int] = set()
    for k, (label, members) in enumerate(groups.items()):
        rows = [row[robot] for robot in members if robot in row]
        placed.update(members)
        if rows:
            axes.scatter(
                xy[rows, 0], xy[rows, 1], s=18, marker=_MARKERS[k % len(_MARKERS)], label=label
            )
    others = [row[robot] for robot in ids if robot not in placed]
    if others:
        axes.scatter(
            xy[others, 0], xy[others, 1], s=18, marker="o", label="robot" if not groups else "other"
        )
    held = xy[carrying]
    if len(held):
        axes.scatter(
            held[:, 0], held[:, 1], s=60, facecolors="none", edgecolors="black", label="carrying"
        )
    width, height = world
    margin = 0.03 * max(width, height)
    axes.set_xlim(-margin, width + margin)
    axes.set_ylim(-margin, height + margin)
    axes.set_aspect("equal")
    axes.grid(True, linewidth=0.5, alpha=0.5)
    axes.set_title(f"{title} (sample at t = {t:g} s)", fontsize=9)
    axes.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=7)
    canvas.draw()  # type: ignore[no-untyped-call] # matplotlib leaves it unannotated
    rgba = np.asarray(canvas.buffer_rgba())  # type: ignore[no-untyped-call]
    return np.ascontiguousarray(rgba[:, :, :3])
