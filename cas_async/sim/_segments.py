"""The vectorised half of the Environment: every robot's motion in numpy arrays.

One row per robot holds its current motion segment (absolute times, end points
and the translation's speed phases), so the positions of all robots at an
instant come from a handful of array operations, with no Python loop per robot.
The per-robot :class:`~cas_async.sim._kinematics.Motion` stays the reference;
this table is its fast path and must agree with it.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
import numpy.typing as npt

from ._kinematics import Motion

__all__ = ["SegmentTable"]

# Columns of the row table: the absolute instant the translation starts, the
# absolute instant the motion ends (-inf: standing), start and end points, length.
_T_TRANSLATE, _T_END, _X0, _Y0, _X1, _Y1, _LENGTH = range(7)
_COLUMNS: Final = 7

# Fields of a phase: start (seconds into the translation), distance at start,
# speed at start, acceleration. Unused phase slots start at +inf, never in force.
_P_START, _P_DIST, _P_SPEED, _P_ACCEL = range(4)

_UNUSED: Final = [math.inf, 0.0, 0.0, 0.0]
"""The fields of an unused phase slot."""

_INITIAL_CAPACITY: Final = 64


class SegmentTable:
    """Rows of motion segments, addressed by a dense index ``0 .. len-1``."""

    def __init__(self) -> None:
        self._n = 0
        self._rows = np.zeros((_INITIAL_CAPACITY, _COLUMNS))
        self._keep_phases(self._empty_phases(_INITIAL_CAPACITY, 1))

    def __len__(self) -> int:
        return self._n

    def _keep_phases(self, phases: npt.NDArray[np.float64]) -> None:
        """Holds ``phases``, and its rows flat: one assignment writes a row's phases."""
        self._phases = phases
        self._flat = phases.reshape(phases.shape[0], -1)

    @staticmethod
    def _empty_phases(rows: int, width: int) -> npt.NDArray[np.float64]:
        phases = np.zeros((rows, width, 4))
        phases[:, :, _P_START] = math.inf
        return phases

    def append(self, start_time: float, motion: Motion) -> None:
        """Adds a row at index ``len(self)``."""
        if self._n == self._rows.shape[0]:
            grown = 2 * self._n
            rows = np.zeros((grown, _COLUMNS))
            rows[: self._n] = self._rows[: self._n]
            phases = self._empty_phases(grown, self._phases.shape[1])
            phases[: self._n] = self._phases[: self._n]
            self._rows = rows
            self._keep_phases(phases)
        self._n += 1
        self.set(self._n - 1, start_time, motion)

    def set(self, index: int, start_time: float, motion: Motion) -> None:
        """Replaces row ``index`` with ``motion`` started at absolute ``start_time``."""
        start, end = motion.start, motion.end
        t_end = start_time + motion.duration if motion.duration > 0 else -math.inf
        self._rows[index] = (
            start_time + motion.rotation_time,
            t_end,
            start.x,
            start.y,
            end.x,
            end.y,
            motion.length,
        )
        phases = () if motion.profile is None else motion.profile.starts()
        width = self._phases.shape[1]
        if len(phases) > width:
            wider = self._empty_phases(self._phases.shape[0], len(phases))
            wider[:, :width] = self._phases
            self._keep_phases(wider)
            width = len(phases)
        values: list[float] = []
        for t0, d0, phase in phases:
            values += (t0, d0, phase.speed, phase.acceleration)
        self._flat[index] = values + _UNUSED * (width - len(phases))

    def blank(self, index: int) -> None:
        """Row ``index`` is nowhere: its position is NaN at every instant (a hidden robot)."""
        self._rows[index] = (-math.inf, -math.inf, math.nan, math.nan, math.nan, math.nan, 0.0)
        self._flat[index] = _UNUSED * self._phases.shape[1]

    def delete(self, index: int) -> None:
        """Removes row ``index``; later rows move up by one (order is kept)."""
        n = self._n
        self._rows[index : n - 1] = self._rows[index + 1 : n]
        self._phases[index : n - 1] = self._phases[index + 1 : n]
        self._n = n - 1

    def positions(self, t: float) -> npt.NDArray[np.float64]:
        """Every row's position at absolute instant ``t``, shape ``(len, 2)``.

        A row is at its start point until its translation starts (so also before
        its segment began: history is not kept), at its end point once the motion
        is over, and in between at the closed-form distance of its profile.
        """
        return self._evaluate(t, self._rows[: self._n], None)

    def positions_of(self, t: float, indices: npt.NDArray[np.intp]) -> npt.NDArray[np.float64]:
        """The positions of rows ``indices`` at absolute instant ``t``, shape ``(len(indices), 2)``.

        Row for row the same numbers as :meth:`positions` (the same arithmetic on
        each row), in time proportional to ``len(indices)``.
        """
        return self._evaluate(t, self._rows[indices], indices)

    def position(self, index: int, t: float) -> tuple[float, float]:
        """Row ``index``'s position at absolute instant ``t``: that row of :meth:`positions`.

        The same arithmetic on plain floats, in the same order (IEEE doubles either
        way), for the single rows a query asks about: numpy's cost per call is most
        of the work for one row.
        """
        t_translate, t_end, x0, y0, x1, y1, length = self._rows[index].tolist()
        tau = t - t_translate
        if tau <= 0:
            return x0, y0
        if not t < t_end:
            return x1, y1
        if not length > 0:  # under way without translating (no motion does): numpy's NaNs
            x, y = self.positions_of(t, np.array([index], dtype=np.intp))[0].tolist()
            return x, y
        phases = self._phases[index].tolist()
        start, covered, speed, acceleration = phases[-1]  # in force: the last one started
        for phase in phases:
            if phase[_P_START] > tau:
                break
            start, covered, speed, acceleration = phase
        into = tau - start
        travelled = covered + into * (speed + 0.5 * acceleration * into)
        # np.maximum's and np.minimum's choices: NaN stays NaN, -0.0 becomes 0.0.
        clipped = travelled if travelled > 0.0 or travelled != travelled else 0.0
        share = min(clipped, length) / length
        return x0 + share * (x1 - x0), y0 + share * (y1 - y0)

    def box(self, index: int) -> tuple[float, float, float, float]:
        """Row ``index``'s segment ``(x0, y0, x1, y1)``: the row is on it at every instant."""
        row = self._rows[index]
        return (float(row[_X0]), float(row[_Y0]), float(row[_X1]), float(row[_Y1]))

    def _evaluate(
        self,
        t: float,
        rows: npt.NDArray[np.float64],
        indices: npt.NDArray[np.intp] | None,
    ) -> npt.NDArray[np.float64]:
        """Positions of ``rows``, which are rows ``indices`` of the table (``None``: all)."""
        tau = t - rows[:, _T_TRANSLATE]
        waiting = tau <= 0
        xy = np.where(waiting[:, None], rows[:, _X0 : _Y0 + 1], rows[:, _X1 : _Y1 + 1])
        moving = np.flatnonzero(~waiting & (t < rows[:, _T_END]))
        if moving.size:
            table_rows = moving if indices is None else indices[moving]
            self._place_moving(xy, moving, table_rows, tau[moving], rows[moving])
        return xy

    def _place_moving(
        self,
        xy: npt.NDArray[np.float64],
        moving: npt.NDArray[np.intp],
        table_rows: npt.NDArray[np.intp],
        tau: npt.NDArray[np.float64],
        rows: npt.NDArray[np.float64],
    ) -> None:
        phases = self._phases[table_rows]
        # The phase in force is the last one that has started. The first starts at 0,
        # before ``tau``; a row without phases has only padding, in any slot.
        current = np.zeros(moving.size, dtype=np.intp)
        for later in range(1, phases.shape[1]):
            current += phases[:, later, _P_START] <= tau
        phase = phases[np.arange(moving.size), current].T
        into = tau - phase[_P_START]
        travelled = phase[_P_DIST] + into * (phase[_P_SPEED] + 0.5 * phase[_P_ACCEL] * into)
        length = rows[:, _LENGTH]
        share = np.minimum(np.maximum(travelled, 0.0), length) / length
        start = rows[:, _X0 : _Y0 + 1]
        xy[moving] = start + share[:, None] * (rows[:, _X1 : _Y1 + 1] - start)
