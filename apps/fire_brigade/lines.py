"""Whether the Transporters stand in lines: the thesis's §5.8 result, as one number.

The thesis expects the Transporters to converge on the paths from the Generators to
the Sinks and pass buckets along them "with minimal movement" (§5.8.1, Figs. 34-36).
:class:`LineShare` measures that: the share of Transporters that stand *on a line*,
within ``near`` of a Generator-Sink segment and farther than ``away`` from every
station. The second condition matters: a crowd parked on the Sinks (or waiting at
the Generators) is close to the segments too, but it is not a line.

Each Generator's segment goes to its nearest Sink, the one its buckets go to (see
the Goal layer). The scenario runner evaluates the measure on every sample of the
robots' positions and on every exchange snapshot (``Mission.measures``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from typing import Final

import numpy as np
import numpy.typing as npt

from .base import Point

__all__ = ["LineShare", "segments"]

_FloatArray = npt.NDArray[np.float64]

NEAR: Final = 0.5
"""How close to a segment a Transporter stands on the line."""
AWAY: Final = 1.0
"""How far from every station it must be: a robot parked on a Sink is not in a line."""


def segments(generators: Sequence[Point], sinks: Sequence[Point]) -> list[tuple[Point, Point]]:
    """Each Generator with its nearest Sink (ties to the first listed), as segments."""
    if not sinks:
        return []
    return [(g, min(sinks, key=lambda s: math.dist(g, s))) for g in generators]


class LineShare:
    """The share of Transporters on a Generator-Sink line (see the module docs).

    Called with the robots' ids and positions (one row per id), it returns a number
    between 0 and 1 (0 when there is no Transporter among the ids).

    Args:
        transporters: the Transporters' ids; other robots are ignored.
        lines: the segments, from :func:`segments`.
        stations: every Generator's and Sink's position.
        near: the distance to a segment within which a Transporter is on it.
        away: the distance from every station beyond which it counts.
    """

    def __init__(
        self,
        transporters: Sequence[int],
        lines: Sequence[tuple[Point, Point]],
        stations: Sequence[Point],
        *,
        near: float = NEAR,
        away: float = AWAY,
    ) -> None:
        self._transporters = frozenset(transporters)
        self._starts = np.array([a for a, _ in lines], dtype=np.float64).reshape(-1, 2)
        self._ends = np.array([b for _, b in lines], dtype=np.float64).reshape(-1, 2)
        self._stations = np.array(stations, dtype=np.float64).reshape(-1, 2)
        self._near, self._away = near, away
        self._rows: tuple[tuple[int, ...], npt.NDArray[np.intp]] | None = None
        # Each segment's and station's band of x, where the robots it may count are.
        self._segment_bands = (
            np.minimum(self._starts[:, 0], self._ends[:, 0]) - near,
            np.maximum(self._starts[:, 0], self._ends[:, 0]) + near,
        )
        self._station_bands = (self._stations[:, 0] - away, self._stations[:, 0] + away)

    def __call__(self, ids: Sequence[int], xy: _FloatArray) -> float:
        """The share among the Transporters of ``ids`` at positions ``xy``."""
        rows = self._transporter_rows(ids)
        if not len(rows):
            return 0.0
        points = np.asarray(xy, dtype=np.float64)[rows]
        # Each segment and station looks only at the robots in its band of x (sorted
        # once): a swarm of thousands against hundreds of segments stays cheap.
        order = np.argsort(points[:, 0], kind="stable")
        xs = points[order, 0]
        on_line = np.zeros(len(points), dtype=np.bool_)
        for index, band in self._in_bands(order, xs, self._segment_bands):
            near = _distance_to_segment(points[band], self._starts[index], self._ends[index])
            on_line[band[near <= self._near]] = True
        for index, band in self._in_bands(order, xs, self._station_bands):
            close = np.hypot(*(points[band] - self._stations[index]).T) <= self._away
            on_line[band[close]] = False
        return float(np.count_nonzero(on_line)) / len(rows)

    @staticmethod
    def _in_bands(
        order: npt.NDArray[np.intp], xs: _FloatArray, bands: tuple[_FloatArray, _FloatArray]
    ) -> Iterator[tuple[int, npt.NDArray[np.intp]]]:
        """Each band (by index) that holds robots, and their rows: ``xs`` is sorted by ``order``."""
        lows = np.searchsorted(xs, bands[0]).tolist()
        highs = np.searchsorted(xs, bands[1], side="right").tolist()
        for index, (low, high) in enumerate(zip(lows, highs, strict=True)):
            if low < high:
                yield index, order[low:high]

    def _transporter_rows(self, ids: Sequence[int]) -> npt.NDArray[np.intp]:
        key = tuple(ids)
        if self._rows is None or self._rows[0] != key:
            rows = [k for k, robot in enumerate(key) if robot in self._transporters]
            self._rows = (key, np.array(rows, dtype=np.intp))
        return self._rows[1]


def _distance_to_segment(points: _FloatArray, start: _FloatArray, end: _FloatArray) -> _FloatArray:
    """For each point, its distance to the segment from ``start`` to ``end``."""
    span = end - start
    length2 = float(span @ span)
    offset = points - start
    fraction = np.clip(offset @ span / length2, 0.0, 1.0) if length2 > 0 else 0.0
    nearest = start + np.multiply.outer(fraction, span)
    distance: _FloatArray = np.hypot(*(points - nearest).T)
    return distance
