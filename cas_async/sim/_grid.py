"""A uniform grid of square cells over rectangles: which rows may be near a point.

The Environment's range queries must not look at every robot of a large swarm.
Each robot's current motion is a straight segment, and whatever instant is asked
about, the robot is on that segment (at its start before it moves, at its end
after). So the grid files each row under every cell its segment's bounding box
overlaps, and a query collects the rows filed under the cells its own box
overlaps: a superset of the rows inside the box, which the caller then filters
exactly. A row is refiled only when its motion changes, in time proportional to
the cells its box covers, not to the number of rows.
"""

from __future__ import annotations

import math
from typing import Final, final

import numpy as np
import numpy.typing as npt

from .._body._positions import Positions

__all__ = ["CellGrid", "nearest_first"]

_Span = tuple[int, int, int, int]  # x0, y0, x1, y1: inclusive cell indices

# Boxes are widened by this much relative to their coordinates' magnitude: a point
# computed on a segment may lie a rounding error outside the segment's box.
_SLACK: Final = 1e-9


@final
class CellGrid:
    """Rows filed under the square cells their boxes overlap.

    Args:
        cell: the side of a cell, a finite number > 0.

    Raises:
        ValueError: ``cell`` is not a finite number > 0.
    """

    __slots__ = ("_cell", "_cells", "_spans")

    def __init__(self, cell: float) -> None:
        if not (math.isfinite(cell) and cell > 0):
            raise ValueError(f"CellGrid: cell must be a finite number > 0, got {cell!r}")
        self._cell = float(cell)
        self._cells: dict[tuple[int, int], set[int]] = {}
        self._spans: dict[int, _Span] = {}

    def __len__(self) -> int:
        return len(self._spans)

    def __contains__(self, row: object) -> bool:
        return row in self._spans

    @property
    def cell(self) -> float:
        """The side of a cell."""
        return self._cell

    def _span(self, x0: float, y0: float, x1: float, y1: float) -> _Span:
        """The cells a box overlaps, the box widened by the rounding slack."""
        slack = _SLACK * max(1.0, abs(x0), abs(y0), abs(x1), abs(y1))
        size = self._cell
        return (
            math.floor((min(x0, x1) - slack) / size),
            math.floor((min(y0, y1) - slack) / size),
            math.floor((max(x0, x1) + slack) / size),
            math.floor((max(y0, y1) + slack) / size),
        )

    def place(self, row: int, x0: float, y0: float, x1: float, y1: float) -> None:
        """Files ``row`` under the box with corners ``(x0, y0)`` and ``(x1, y1)`` (any order).

        A row already placed moves: it is only under the new box's cells afterwards.

        Raises:
            ValueError: a coordinate is not finite.
        """
        if not all(math.isfinite(v) for v in (x0, y0, x1, y1)):
            raise ValueError(
                f"CellGrid: row {row}'s box must have finite corners, "
                f"got ({x0!r}, {y0!r}), ({x1!r}, {y1!r})"
            )
        span = self._span(x0, y0, x1, y1)
        old = self._spans.get(row)
        if old == span:
            return
        if old is not None:
            self._unfile(row, old)
        self._spans[row] = span
        cells = self._cells
        for ix in range(span[0], span[2] + 1):
            for iy in range(span[1], span[3] + 1):
                cells.setdefault((ix, iy), set()).add(row)

    def remove(self, row: int) -> None:
        """Takes ``row`` out of the grid (nothing happens if it is not in it)."""
        old = self._spans.pop(row, None)
        if old is not None:
            self._unfile(row, old)

    def _unfile(self, row: int, span: _Span) -> None:
        cells = self._cells
        for ix in range(span[0], span[2] + 1):
            for iy in range(span[1], span[3] + 1):
                key = (ix, iy)
                filed = cells[key]
                filed.discard(row)
                if not filed:
                    del cells[key]

    def cells_over(self, x0: float, y0: float, x1: float, y1: float) -> int:
        """How many cells a query of this box would visit (to decide whether it is worth it)."""
        span = self._span(x0, y0, x1, y1)
        return (span[2] - span[0] + 1) * (span[3] - span[1] + 1)

    def rows_near(self, x0: float, y0: float, x1: float, y1: float) -> set[int]:
        """Every row whose box overlaps the box from ``(x0, y0)`` to ``(x1, y1)``, and maybe more.

        Rows whose boxes share a cell with the query's box are included too: the
        caller filters by exact positions. Visits :meth:`cells_over` cells, or the
        occupied cells if there are fewer of those.
        """
        span = self._span(x0, y0, x1, y1)
        cells = self._cells
        found: set[int] = set()
        visits = (span[2] - span[0] + 1) * (span[3] - span[1] + 1)
        if visits > len(cells):
            for (ix, iy), filed in cells.items():
                if span[0] <= ix <= span[2] and span[1] <= iy <= span[3]:
                    found |= filed
            return found
        for ix in range(span[0], span[2] + 1):
            for iy in range(span[1], span[3] + 1):
                rows = cells.get((ix, iy))
                if rows:
                    found |= rows
        return found


def nearest_first(
    ids: npt.NDArray[np.int64],
    xy: npt.NDArray[np.float64],
    here: npt.NDArray[np.float64],
    radius: float,
    own: int,
) -> Positions:
    """The rows of ``ids``/``xy`` within ``radius`` of ``here``, row ``own`` left out.

    Nearest first, ties broken by id. Every row's distance is computed on its own,
    so a subset of rows gets the same numbers as the whole table.
    """
    offsets = xy - here
    squared = np.einsum("ij,ij->i", offsets, offsets)
    inside = squared <= radius * radius
    inside[own] = False
    found = np.flatnonzero(inside)
    order = found[np.lexsort((ids[found], squared[found]))]
    found_ids, found_xy = ids[order], xy[order]
    found_ids.flags.writeable = found_xy.flags.writeable = False
    return Positions(found_ids, found_xy)
