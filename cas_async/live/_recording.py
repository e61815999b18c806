"""A run directory as a recording: what the replay and the export read, and ``scene.json``.

A finished run's directory holds all a replay needs: ``trace.csv`` (every sample's
positions and carriers, and the exchange snapshots), ``results.json`` (the
groups, the target, the measures over time, the deliveries) and ``scene.json``
(the world's size and the application's static scene, written by ``run``; a
directory without it replays without a scene).

:class:`Recording` reads the directory as untrusted input (see
:mod:`._run_files`): every file, row and field it uses is checked when it opens,
so that it fails then, with one line naming the file, line and field, or never.
It indexes ``trace.csv`` in that one pass (where each sample's rows begin) and
reads a sample's rows again when asked, so a trace of millions of rows is not
held in memory.
"""

from __future__ import annotations

import json
import math
from bisect import bisect_right
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Final, final

import numpy as np
import numpy.typing as npt

from ..scenario import ScenarioRun, Scene
from ..scenario.output import atomic_text_file
from ._protocol import UNKNOWN
from ._run_files import (
    ID_LIMIT,
    LINE_LIMIT,
    POSITION_LIMIT,
    RESULTS_LIMIT,
    SCENE_LIMIT,
    TIME_LIMIT,
    TRACE_LIMIT,
    Fields,
    RecordingError,
    open_regular,
    read_json,
    show,
)

__all__ = ["Recording", "RecordingError", "Sample", "write_scene"]

SCENE_FORMAT: Final = "cas_async scene"
_HEADER: Final = b"t,robot,x,y,exchange,carrying"


def write_scene(run: ScenarioRun, out: Path) -> Path:
    """Writes ``out/scene.json``: the world's size and the mission's scene; returns its path."""
    world = run.result.config.get("world", {})
    path = Path(out) / "scene.json"
    data = {
        "format": SCENE_FORMAT,
        "version": 1,
        "world": {
            "width": float(world.get("width", 0.0)),
            "height": float(world.get("height", 0.0)),
        },
        "scene": run.mission.scene.to_json(),
    }
    with atomic_text_file(path) as stream:
        json.dump(data, stream, indent=1)
        stream.write("\n")
    return path


@dataclass(frozen=True, slots=True)
class Sample:
    """One sample of a recording.

    Attributes:
        index: its index among the samples (a frame's ``seq``).
        t: simulated instant.
        xy: every robot's position, shape ``(n, 2)``, in :attr:`Recording.robots` order.
        carrying: which robots carried something, shape ``(n,)``.
        done: the objective's count then (deliveries up to ``t``).
        detail: its second count (exchanges up to ``t``), or ``UNKNOWN``.
        measures: each measure's value at this sample (NaN where not recorded).
    """

    index: int
    t: float
    xy: npt.NDArray[np.float64]
    carrying: npt.NDArray[np.bool_]
    done: int
    detail: int
    measures: tuple[float, ...]


@final
class Recording:
    """A finished run's directory, read for a replay or an export (see the module docs).

    Args:
        run_dir: the directory ``run`` wrote.

    Raises:
        RecordingError: a file is missing, is no regular file of the directory, is
            too large, or holds a value out of its type or range (naming the file,
            and the line and field).
    """

    def __init__(self, run_dir: Path) -> None:
        self.path = Path(run_dir)
        if not self.path.is_dir():
            raise RecordingError(f"{self.path}: not a directory (expected a run's output)")
        self.results = self._read("results.json", RESULTS_LIMIT)
        fields = Fields(self.path / "results.json", self.results)
        self.world, self.scene = self._scene(fields)
        self._trace = self.path / "trace.csv"
        self.robots, self._blocks = _index(self._trace, self.path)
        self.times = [t for t, _, _, exchange in self._blocks if exchange is None]
        self._samples = [block for block in self._blocks if block[3] is None]
        self.exchanges = [(t, count) for t, _, _, count in self._blocks if count is not None]
        """Exchange snapshots: ``(t, count)``, in order."""
        self._exchange_times = [t for t, _ in self.exchanges]
        self.deliveries = fields.times("delivery_times")
        series = fields.series("series", len(self.times))
        self.measures = list(series)
        self._series = list(series.values())
        self.groups = fields.groups("groups")
        """The robots of each group, by name (``results.json``'s ``groups``)."""
        self.info = _info(fields)
        """What the replay's hello says of the run, checked: ``app``, ``scenario``,
        ``seed``, ``kind``, ``item_name``, ``verb``, ``target``, ``end``."""
        self._no_exchanges = self.info["kind"] == "items" and fields.integer("exchanges") == 0

    # -- the files ---------------------------------------------------------------------

    def _read(self, name: str, limit: int) -> dict[str, Any]:
        path = self.path / name
        try:
            return read_json(path, self.path, limit)
        except FileNotFoundError:
            raise RecordingError(f"{path}: missing (is this a run's output directory?)") from None

    def _scene(self, results: Fields) -> tuple[tuple[float, float], Scene]:
        path = self.path / "scene.json"
        if not path.exists() and not path.is_symlink():  # an older run: the scenario's world
            world = results.table("config").table("world")
            size = (world.number("width", high=POSITION_LIMIT),
                    world.number("height", high=POSITION_LIMIT))  # fmt: skip
            return (size[0] or 0.0, size[1] or 0.0), Scene()
        data = self._read("scene.json", SCENE_LIMIT)
        if data.get("format") != SCENE_FORMAT:
            raise RecordingError(
                f"{path}: format: expected {SCENE_FORMAT!r}, got {show(data.get('format'))}"
            )
        if "world" not in data:
            raise RecordingError(f"{path}: world: missing")
        world = Fields(path, data).table("world")
        width, height = (
            world.number(side, None, low=math.ulp(0.0), high=POSITION_LIMIT)
            for side in ("width", "height")
        )
        if width is None or height is None:
            raise RecordingError(f"{path}: world: expected its width and height")
        try:
            return (width, height), Scene.from_json(data.get("scene", {}))
        except ValueError as exc:
            raise RecordingError(f"{path}: {exc}") from None

    # -- reading -----------------------------------------------------------------------

    def __len__(self) -> int:
        return len(self._samples)

    @property
    def end(self) -> float:
        """The last sample's instant (0 for none)."""
        return self.times[-1] if self.times else 0.0

    def index_at(self, t: float) -> int:
        """The index of the last sample at or before ``t`` (the first, before it)."""
        return max(0, bisect_right(self.times, t) - 1)

    def sample(self, index: int) -> Sample:
        """Sample ``index``, read from ``trace.csv``.

        Raises:
            IndexError: no such sample.
            RecordingError: its rows changed since the recording was opened.
        """
        if not 0 <= index < len(self._samples):
            raise IndexError(f"sample {index} of {len(self._samples)}")
        t, offset, line, _ = self._samples[index]
        xy, carrying = _rows(self._trace, self.path, offset, line, self.robots)
        done = bisect_right(self.deliveries, t)
        detail = UNKNOWN  # known from the exchange snapshots, or a run with none
        if self.exchanges:
            k = bisect_right(self._exchange_times, t)
            detail = self.exchanges[k - 1][1] if k else 0
        elif self._no_exchanges:
            detail = 0
        measures = tuple(series[index] for series in self._series)
        return Sample(index, t, xy, carrying, done, detail, measures)


def _info(fields: Fields) -> dict[str, Any]:
    """What ``results.json`` says of the run beyond the samples, each field checked."""
    kind = fields.text("kind", "items")  # an item mission's results name no kind
    return {
        "app": fields.text("app"),
        "scenario": fields.text("scenario"),
        "seed": fields.integer("seed"),
        "kind": kind,
        "item_name": fields.text("item_name", "item"),
        "verb": fields.text("verb", "delivered" if kind == "items" else "done"),
        "target": fields.integer("target"),
        "end": {
            "t": fields.number("sim_time", None),
            "status": fields.text("status", "") or None,
            "makespan": fields.number("makespan", None),
            "done": fields.integer("delivered") if fields.has("delivered") else None,
        },
    }


_Block = tuple[float, int, int, "int | None"]  # t, byte offset, line number, exchange count


def _index(path: Path, run_dir: Path) -> tuple[list[int], list[_Block]]:
    """The robots (the first sample's order) and every block of rows, each row checked."""
    try:
        with open_regular(path, run_dir, TRACE_LIMIT) as stream:
            return _Index(path, stream).read()
    except FileNotFoundError:
        raise RecordingError(f"{path}: missing (is this a run's output directory?)") from None


@final
class _Index:
    """One pass over ``trace.csv``: every row checked, where each block begins."""

    def __init__(self, path: Path, stream: IO[bytes]) -> None:
        self._path = path
        self._stream = stream
        self._number = 0  # the line read last

    def _line(self) -> bytes:
        line = self._stream.readline(LINE_LIMIT + 1)
        if line:
            self._number += 1
        if len(line) > LINE_LIMIT:
            raise self._wrong(None, f"longer than {LINE_LIMIT} bytes (a row is a few dozen)")
        return line

    def _wrong(self, field: str | None, what: str) -> RecordingError:
        where = f"{field}: " if field else ""
        return RecordingError(f"{self._path}: line {self._number}: {where}{what}")

    def read(self) -> tuple[list[int], list[_Block]]:
        """The robots (the first block's order) and the blocks (see :class:`_Index`)."""
        head = self._line()
        if head.rstrip(b"\r\n") != _HEADER:
            raise RecordingError(f"{self._path}: line 1: expected the header {_HEADER.decode()!r}")
        offset = len(head)
        robots: list[int] = []
        seen: set[int] = set()
        blocks: list[_Block] = []
        key = (b"", b"")  # the (t, exchange) fields of the block being read
        n = 0  # robots per block, once the first block has ended
        k = 0  # the row's place in its block
        last_t, last_count = 0.0, 0
        while line := self._line():
            fields = line.rstrip(b"\r\n").split(b",")
            if len(fields) != 6:
                raise self._wrong(None, f"expected 6 fields, got {len(fields)}")
            robot = self._robot(fields[1])
            here = (fields[0], fields[4])
            if n == 0 and blocks and (here != key or robot in seen):
                n = k = len(robots)  # the first block ended: it named the robots, in order
            if not blocks or (n and k == n):
                t, count = self._block_of(fields, last_t, last_count)
                last_t, last_count = t, count or last_count
                blocks.append((t, offset, self._number, count))
                key, k = here, 0
            elif n and here != key:
                raise self._wrong(
                    "t", f"expected the t and exchange of its sample's first row ({k} of {n})"
                )
            if n == 0:
                robots.append(robot)
                seen.add(robot)
            elif robot != robots[k]:
                raise self._wrong("robot", f"expected robot {robots[k]}'s row, got {robot}")
            self._position(fields)
            if fields[5] not in (b"0", b"1"):
                raise self._wrong("carrying", f"expected 0 or 1, got {show(fields[5])}")
            k += 1
            offset += len(line)
        if n and k != n:
            raise self._wrong(None, f"the file ends within a sample ({k} of its {n} robots' rows)")
        return robots, blocks

    def _robot(self, field: bytes) -> int:
        try:
            robot = int(field)
        except ValueError:
            raise self._wrong("robot", f"expected an integer, got {show(field)}") from None
        if not -ID_LIMIT < robot < ID_LIMIT:
            raise self._wrong("robot", f"expected an id within 2**53, got {show(field)}")
        return robot

    def _block_of(
        self, fields: list[bytes], last_t: float, last_count: int
    ) -> tuple[float, int | None]:
        try:
            t = float(fields[0])
        except ValueError:
            t = math.nan
        if not 0 <= t <= TIME_LIMIT:  # NaN too
            raise self._wrong(
                "t", f"expected a number from 0 to {TIME_LIMIT:g}, got {show(fields[0])}"
            )
        if t < last_t:
            raise self._wrong("t", f"{show(fields[0])} comes before the rows above ({last_t!r})")
        exchange = fields[4].strip()
        if not exchange:
            return t, None
        try:
            count = int(exchange)
        except ValueError:
            count = 0
        if count < 1:
            raise self._wrong("exchange", f"expected a count from 1, got {show(exchange)}")
        if count <= last_count:
            raise self._wrong("exchange", f"{count} after {last_count}: the counts must increase")
        return t, count

    def _position(self, fields: list[bytes]) -> None:
        for name, field in (("x", fields[2]), ("y", fields[3])):
            try:
                value = float(field)
            except ValueError:
                value = math.nan
            if not -POSITION_LIMIT <= value <= POSITION_LIMIT:  # NaN too
                raise self._wrong(
                    name, f"expected a number within {POSITION_LIMIT:g}, got {show(field)}"
                )


def _rows(
    path: Path, run_dir: Path, offset: int, number: int, robots: list[int]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    xy = np.empty((len(robots), 2), dtype=np.float64)
    carrying = np.zeros(len(robots), dtype=np.bool_)
    try:
        with open_regular(path, run_dir, TRACE_LIMIT) as stream:
            stream.seek(offset)
            for k, robot in enumerate(robots):
                fields = stream.readline(LINE_LIMIT + 1).split(b",")
                at = number + k
                if len(fields) != 6 or fields[1] != str(robot).encode():
                    raise RecordingError(
                        f"{path}: line {at}: expected robot {robot}'s row (the file changed?)"
                    )
                xy[k] = float(fields[2]), float(fields[3])
                carrying[k] = fields[5].strip() == b"1"
    except FileNotFoundError:
        raise RecordingError(f"{path}: gone since the recording was opened") from None
    except ValueError as exc:  # a row that changed since it was checked
        raise RecordingError(f"{path}: changed since the recording was opened: {exc}") from None
    return xy, carrying
