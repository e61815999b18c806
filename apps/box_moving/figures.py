"""``objects.png``: where the robots went, and where each object went, from the Floor's records.

Imported only when figures are drawn (matplotlib is the optional ``plots``
extra); drawn on an Agg canvas, never through pyplot.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

from cas_async.scenario.output import Trace

from .floor import Floor

__all__ = ["draw_objects"]

_DPI: Final = 100
_SOLO: Final = "tab:blue"
_JOINT: Final = "tab:orange"
_LEFT: Final = "tab:gray"


def draw_objects(floor: Floor, trace: Trace, world: tuple[float, float], path: Path) -> Path:
    """Draws the robots' paths and every object's start, path and drop point into ``path``.

    Robots' paths come from the trace's samples (thin grey lines, ids at the
    start). Each object is a square where it lay; a moved object's path (the
    Floor's record) ends at its drop point, in blue for a solo carry and orange
    for a joint one, labelled ``#id: carriers``; an object not moved stays grey.
    The drop zone is the dashed circle.

    Returns:
        ``path``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Rectangle

    # The plot keeps the world's proportions; the legend takes the right-hand margin.
    figure = Figure(figsize=(10, max(4.0, 7.2 * world[1] / world[0] + 1.2)), dpi=_DPI)
    FigureCanvasAgg(figure)
    figure.suptitle("box moving: objects and robots")
    figure.subplots_adjust(left=0.07, right=0.78, bottom=0.08, top=0.92)
    axes = figure.add_subplot()
    (cx, cy), radius = floor.zone
    axes.add_patch(Circle((cx, cy), radius, fill=False, linestyle="--", color="tab:green"))
    positions = trace.positions
    for k, robot in enumerate(trace.ids):
        if len(positions):
            xs, ys = positions[:, k, 0], positions[:, k, 1]
            axes.plot(xs, ys, color="0.6", linewidth=0.7, zorder=1)
            axes.annotate(f"R{robot}", (xs[0], ys[0]), fontsize=7, color="0.3")
    moved = {delivery.obj: delivery for delivery in floor.deliveries()}
    for box in floor.boxes:
        delivery = moved.get(box.obj)
        colour = _LEFT if delivery is None else _JOINT if delivery.joint else _SOLO
        half = box.size / 2
        axes.add_patch(
            Rectangle(
                (box.x - half, box.y - half), box.size, box.size, fill=False, color=colour, zorder=2
            )
        )
        axes.annotate(f"#{box.obj} ({box.weight:g})", (box.x, box.y - half), fontsize=6)
        if delivery is None:
            continue
        route = floor.path(box.obj)
        axes.plot([p[1] for p in route], [p[2] for p in route], color=colour, linewidth=1.4)
        carriers = "+".join(f"R{robot}" for robot in delivery.carriers)
        axes.plot(box.drop_x, box.drop_y, marker="x", color=colour, zorder=3)
        axes.annotate(
            f"#{box.obj}: {carriers}",
            (box.drop_x, box.drop_y),
            xytext=(3, 3),
            textcoords="offset points",
            fontsize=6,
        )
    axes.legend(
        handles=[
            Line2D([], [], color=_SOLO, label="carried alone"),
            Line2D([], [], color=_JOINT, label="carried by two"),
            Line2D([], [], color=_LEFT, label="not moved"),
            Line2D([], [], color="0.6", linewidth=0.7, label="robot paths"),
        ],
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize=8,
    )
    axes.set_xlim(0, world[0])
    axes.set_ylim(0, world[1])
    axes.set_aspect("equal")
    axes.set_xlabel("x")
    axes.set_ylabel("y")
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=_DPI, format="png")
    return path
