"""Where a fixed set of robots were over simulated time: the data behind the plots.

A :class:`Trace` holds two streams for the same robots, in the same row order:

* regular samples, taken every so often by the runner (:meth:`Trace.sample`);
* exchange snapshots, taken right after an item changed hands (:meth:`Trace.exchange`).

Each record may also say which robots carry an item at that instant (drawn as
carriers in the figures, the ``carrying`` column of ``trace.csv``).

Recording only appends to Python lists (a run may record tens of thousands of
samples for a few hundred robots); the numpy views are built when first asked
for and kept until the next record.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import Counter
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, final

import numpy as np
import numpy.typing as npt

from ..._errors import SimulationError
from ._atomic_files import AtomicFile

__all__ = ["Trace", "TraceCsv"]

_FloatArray = npt.NDArray[np.float64]
_IntArray = npt.NDArray[np.int64]
_BoolArray = npt.NDArray[np.bool_]


class Trace:
    """Positions of a fixed set of robots, sampled over simulated time.

    Every recorded array has shape ``(n, 2)`` with row ``k`` belonging to ``ids[k]``.
    It is copied on record (the caller's array may be a read-only shared cache),
    and every array the trace hands out is read-only.

    Args:
        ids: the robots, in the row order of every array recorded; no duplicates.

    Raises:
        SimulationError: an id appears twice.
    """

    __slots__ = (
        "_cache",
        "_carrying",
        "_ex_carrying",
        "_ex_counts",
        "_ex_times",
        "_ex_xy",
        "_ids",
        "_nobody",
        "_times",
        "_xy",
    )

    def __init__(self, ids: Sequence[int] | _IntArray) -> None:
        self._ids = tuple(int(robot_id) for robot_id in ids)
        twice = sorted(robot_id for robot_id, n in Counter(self._ids).items() if n > 1)
        if twice:
            raise SimulationError(f"Trace: robot ids must be unique, got {twice} more than once")
        self._times: list[float] = []
        self._xy: list[_FloatArray] = []
        self._carrying: list[_BoolArray] = []
        self._ex_counts: list[int] = []
        self._ex_times: list[float] = []
        self._ex_xy: list[_FloatArray] = []
        self._ex_carrying: list[_BoolArray] = []
        self._nobody = np.zeros(len(self._ids), dtype=np.bool_)  # shared: never written
        self._nobody.flags.writeable = False
        # numpy views of the lists above, built on demand; emptied by every record
        self._cache: dict[str, npt.NDArray[Any]] = {}

    def __repr__(self) -> str:
        return (
            f"<Trace {len(self._ids)} robots, {len(self._times)} samples,"
            f" {len(self._ex_times)} exchange snapshots>"
        )

    # -- recording ---------------------------------------------------------------

    def sample(self, t: float, xy: _FloatArray, carrying: _BoolArray | None = None) -> None:
        """Records a regular sample at simulated instant ``t``.

        ``carrying``, shape ``(n,)``, says which robots carry an item (default: none).

        Raises:
            SimulationError: ``t`` is not finite or earlier than the previous sample,
                ``xy`` is not of shape ``(n, 2)`` or ``carrying`` not of shape ``(n,)``.
        """
        t = self._check_time(t, self._times, "sample")
        what = f"sample at t = {t!r}"
        copied, flags = self._copy(xy, what), self._flags(carrying, what)
        self._xy.append(copied)
        self._carrying.append(flags)
        self._times.append(t)
        self._cache.clear()

    def exchange(
        self, t: float, count: int, xy: _FloatArray, carrying: _BoolArray | None = None
    ) -> None:
        """Records a snapshot taken right after the ``count``-th exchange (1-based).

        Snapshots need not cover every exchange, but their counts must increase.
        ``carrying`` is as for :meth:`sample`.

        Raises:
            SimulationError: ``t`` is not finite or earlier than the previous snapshot,
                ``count`` is below 1 or not above the previous one, ``xy`` is not
                of shape ``(n, 2)`` or ``carrying`` not of shape ``(n,)``.
        """
        t = self._check_time(t, self._ex_times, "exchange snapshot")
        count = int(count)
        if count < 1 or (self._ex_counts and count <= self._ex_counts[-1]):
            previous = self._ex_counts[-1] if self._ex_counts else None
            raise SimulationError(
                f"Trace.exchange: count must be at least 1 and above the previous"
                f" snapshot's ({previous}), got {count}"
            )
        copied, flags = (
            self._copy(xy, f"exchange {count}"),
            self._flags(carrying, f"exchange {count}"),
        )
        self._ex_xy.append(copied)
        self._ex_carrying.append(flags)
        self._ex_counts.append(count)
        self._ex_times.append(t)
        self._cache.clear()

    @staticmethod
    def _check_time(t: float, times: list[float], what: str) -> float:
        t = float(t)
        if not math.isfinite(t):
            raise SimulationError(f"Trace: {what} time must be finite, got {t!r}")
        if times and t < times[-1]:
            raise SimulationError(
                f"Trace: {what} times must not decrease, got t = {t!r} after t = {times[-1]!r}"
            )
        return t

    def _copy(self, xy: _FloatArray, what: str) -> _FloatArray:
        copied = np.array(xy, dtype=np.float64, copy=True)
        if copied.shape != (len(self._ids), 2):
            raise SimulationError(
                f"Trace: {what} has shape {copied.shape}, expected ({len(self._ids)}, 2)"
                " (one row per robot id)"
            )
        copied.flags.writeable = False
        return copied

    def _flags(self, carrying: _BoolArray | None, what: str) -> _BoolArray:
        if carrying is None:
            return self._nobody
        copied = np.array(carrying, dtype=np.bool_, copy=True)
        if copied.shape != (len(self._ids),):
            raise SimulationError(
                f"Trace: {what} has carrying of shape {copied.shape},"
                f" expected ({len(self._ids)},) (one flag per robot id)"
            )
        copied.flags.writeable = False
        return copied

    # -- reading -----------------------------------------------------------------

    @property
    def ids(self) -> tuple[int, ...]:
        """The robots, in row order."""
        return self._ids

    @property
    def times(self) -> _FloatArray:
        """Instants of the regular samples, shape ``(samples,)``."""
        return self._array("times", self._times, np.float64)

    @property
    def positions(self) -> _FloatArray:
        """Regular samples, shape ``(samples, n, 2)``."""
        return self._stack("positions", self._xy)

    @property
    def carrying(self) -> _BoolArray:
        """Which robots carried an item at each regular sample, shape ``(samples, n)``."""
        return self._stack_flags("carrying", self._carrying)

    @property
    def exchange_carrying(self) -> _BoolArray:
        """Which robots carried an item at each exchange snapshot, shape ``(snapshots, n)``."""
        return self._stack_flags("exchange_carrying", self._ex_carrying)

    @property
    def exchange_counts(self) -> _IntArray:
        """Exchange count of each snapshot, shape ``(snapshots,)``, increasing."""
        return self._array("exchange_counts", self._ex_counts, np.int64)

    @property
    def exchange_times(self) -> _FloatArray:
        """Instant of each exchange snapshot, shape ``(snapshots,)``."""
        return self._array("exchange_times", self._ex_times, np.float64)

    @property
    def exchange_positions(self) -> _FloatArray:
        """Exchange snapshots, shape ``(snapshots, n, 2)``."""
        return self._stack("exchange_positions", self._ex_xy)

    def at_time(self, t: float) -> _FloatArray:
        """The last regular sample at or before ``t``, shape ``(n, 2)``.

        Raises:
            SimulationError: there is no sample at or before ``t``.
        """
        k = bisect_right(self._times, t) - 1
        if k < 0:
            first = f"the first is at t = {self._times[0]!r}" if self._times else "there are none"
            raise SimulationError(f"Trace: no sample at or before t = {t!r}; {first}")
        return self._xy[k]

    def after_exchange(self, count: int) -> _FloatArray:
        """The snapshot of exchange ``count``, or the last one before it, shape ``(n, 2)``.

        Raises:
            SimulationError: there is no snapshot at or before ``count``.
        """
        k = bisect_right(self._ex_counts, count) - 1
        if k < 0:
            first = (
                f"the first is of exchange {self._ex_counts[0]}"
                if self._ex_counts
                else "there are none"
            )
            raise SimulationError(f"Trace: no snapshot at or before exchange {count}; {first}")
        return self._ex_xy[k]

    def _array(self, key: str, values: list[float] | list[int], dtype: type) -> npt.NDArray[Any]:
        cached = self._cache.get(key)
        if cached is None:
            cached = np.array(values, dtype=dtype)
            cached.flags.writeable = False
            self._cache[key] = cached
        return cached

    def _stack(self, key: str, arrays: list[_FloatArray]) -> _FloatArray:
        return self._stacked(key, arrays, np.empty((0, len(self._ids), 2), dtype=np.float64))

    def _stack_flags(self, key: str, arrays: list[_BoolArray]) -> _BoolArray:
        return self._stacked(key, arrays, np.empty((0, len(self._ids)), dtype=np.bool_))

    def _stacked(self, key: str, arrays: list[Any], empty: npt.NDArray[Any]) -> npt.NDArray[Any]:
        cached = self._cache.get(key)
        if cached is None:
            cached = np.stack(arrays) if arrays else empty
            cached.flags.writeable = False
            self._cache[key] = cached
        return cached

    # -- output ------------------------------------------------------------------

    def write_csv(self, path: Path) -> None:
        """Writes ``t,robot,x,y,exchange,carrying``: one row per robot per sample, in time order.

        ``exchange`` is empty for regular samples and the count for exchange
        snapshots; ``carrying`` is 1 for a robot that carried an item then, else 0.
        At equal times the regular sample comes first. Numbers are
        written with ``repr``, so they read back exactly. The file is replaced
        atomically: an interrupted write leaves the previous file (or none).
        :class:`TraceCsv` writes the same file as the samples come.
        """
        writer = TraceCsv(self, path)
        try:
            writer.close()
        except BaseException:  # also on Ctrl-C: the temporary file must not stay
            writer.discard()
            raise

    def in_time_order(
        self, sample: int = 0, snapshot: int = 0
    ) -> Iterator[tuple[float, str, _FloatArray, int, int]]:
        """The two streams merged in time order, from ``sample`` and ``snapshot`` on.

        Samples come first on ties. Yields ``(t, exchange, xy, next_sample,
        next_snapshot)``: ``exchange`` is ``""`` for a sample and the count for a
        snapshot; the last two say where to go on from after this record.
        """
        i, j = sample, snapshot
        while i < len(self._times) or j < len(self._ex_times):
            if j == len(self._ex_times) or (
                i < len(self._times) and self._times[i] <= self._ex_times[j]
            ):
                i += 1
                yield self._times[i - 1], "", self._xy[i - 1], i, j
            else:
                j += 1
                yield self._ex_times[j - 1], str(self._ex_counts[j - 1]), self._ex_xy[j - 1], i, j


@final
class TraceCsv:
    """``trace.csv`` of a trace that is still growing, written as it grows.

    A row is final once a later instant has been recorded (a snapshot at the same
    instant as a sample still goes after it): :meth:`write_until` writes what is
    final, :meth:`close` the rest, then puts the file in place atomically. A run
    of ten thousand robots thus writes its trace a sample at a time, not a
    million rows at its very end. The format is :meth:`Trace.write_csv`'s.

    Args:
        trace: the trace to write.
        path: the CSV file; it appears (or is replaced) only at :meth:`close`.
    """

    def __init__(self, trace: Trace, path: Path) -> None:
        self._trace = trace
        self._ids = [f"{robot_id}," for robot_id in trace.ids]
        self._file = AtomicFile(Path(path))
        self._file.stream.write("t,robot,x,y,exchange,carrying\n")
        self._next = (0, 0)  # the sample and the snapshot to write next

    @property
    def path(self) -> Path:
        """Where the file goes."""
        return self._file.path

    def write_until(self, t: float) -> None:
        """Writes the rows of every instant before ``t`` not written yet."""
        stream = self._file.stream
        for at, exchange, xy, *after in self._trace.in_time_order(*self._next):
            if at >= t:
                break
            sample, snapshot = after
            trace = self._trace
            carrying = (
                trace._carrying[sample - 1] if exchange == "" else trace._ex_carrying[snapshot - 1]
            )
            stream.write(self._rows(at, exchange, xy, carrying))
            self._next = (sample, snapshot)
        stream.flush()  # the temporary file can be followed as the run goes

    def close(self) -> Path:
        """Writes the remaining rows and puts the file in place; returns its path."""
        self.write_until(math.inf)
        return self._file.commit()

    def discard(self) -> None:
        """Drops the file: the path stays as it was. Idempotent."""
        self._file.discard()

    def _rows(self, t: float, exchange: str, xy: _FloatArray, carrying: _BoolArray) -> str:
        prefix, suffix = f"{t!r},", f",{exchange},"
        return "".join(
            f"{prefix}{robot_id}{x!r},{y!r}{suffix}{int(held)}\n"
            for robot_id, (x, y), held in zip(
                self._ids, xy.tolist(), carrying.tolist(), strict=True
            )
        )
