"""A run directory as a recording: what the replay and the export read, and ``scene.json``.

A finished run's directory holds all a replay needs: ``trace.csv`` (every sample's
positions and carriers, and the exchange snapshots), ``results.json`` (the
groups, the target, the measures over time, the deliveries) and ``scene.json``
(the world's size and the application's static scene, written by ``run``; a
directory without it replays without a scene).

:class:`Recording` indexes ``trace.csv`` once (where each sample's rows begin)
and reads a sample's rows when asked, so a trace of millions of rows is not
held in memory.
"""

from __future__ import annotations

import json
import math
from bisect import bisect_right
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, final

import numpy as np
import numpy.typing as npt

from .. import CasError
from ..scenario import ScenarioRun, Scene
from ..scenario.output import atomic_text_file
from ._protocol import UNKNOWN

__all__ = ["Recording", "RecordingError", "Sample", "write_scene"]

SCENE_FORMAT: Final = "cas_async scene"
_HEADER: Final = b"t,robot,x,y,exchange,carrying"


class RecordingError(CasError, ValueError):
    """A run directory cannot be replayed: names the file, and the line or key at fault."""


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
        RecordingError: a file is missing or malformed (naming it, and where).
    """

    def __init__(self, run_dir: Path) -> None:
        self.path = Path(run_dir)
        if not self.path.is_dir():
            raise RecordingError(f"{self.path}: not a directory (expected a run's output)")
        self.results = _json(self.path / "results.json")
        self.world, self.scene = self._scene()
        self._trace = self.path / "trace.csv"
        self.robots, self._blocks, snapshots = _index(self._trace)
        self.times = [t for t, _, _, exchange in self._blocks if exchange is None]
        self._samples = [block for block in self._blocks if block[3] is None]
        self.exchanges = [(t, count) for t, _, _, count in snapshots if count is not None]
        """Exchange snapshots: ``(t, count)``, in order."""
        self._exchange_times = [t for t, _ in self.exchanges]
        self.deliveries = [float(t) for t in self._key("delivery_times", list)]
        series = self._key("series", dict)
        self.measures = list(series)
        self._series = [self._values(name, series[name]) for name in self.measures]

    # -- the files ---------------------------------------------------------------------

    def _key(self, key: str, kind: type) -> Any:
        value = self.results.get(key)
        if not isinstance(value, kind):
            raise RecordingError(
                f"{self.path / 'results.json'}: {key}: expected {kind.__name__}, "
                f"got {type(value).__name__}"
            )
        return value

    def _scene(self) -> tuple[tuple[float, float], Scene]:
        path = self.path / "scene.json"
        if not path.exists():  # an older run: the world from the scenario as it ran
            world = self.results.get("config", {}).get("world", {})
            return (float(world.get("width", 0.0)), float(world.get("height", 0.0))), Scene()
        data = _json(path)
        if data.get("format") != SCENE_FORMAT:
            raise RecordingError(
                f"{path}: format: expected {SCENE_FORMAT!r}, got {data.get('format')!r}"
            )
        try:
            world = data["world"]
            size = (float(world["width"]), float(world["height"]))
            return size, Scene.from_json(data.get("scene", {}))
        except (KeyError, TypeError, ValueError) as exc:
            raise RecordingError(f"{path}: {exc}") from None

    def _values(self, name: str, series: Any) -> list[float]:
        values = series.get("value") if isinstance(series, dict) else None
        if not isinstance(values, list) or len(values) != len(self.times):
            return [math.nan] * len(self.times)  # not one value per sample: not shown
        return [math.nan if value is None else float(value) for value in values]

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
            RecordingError: its rows are malformed (naming the line).
        """
        if not 0 <= index < len(self._samples):
            raise IndexError(f"sample {index} of {len(self._samples)}")
        t, offset, line, _ = self._samples[index]
        xy, carrying = _rows(self._trace, offset, line, self.robots)
        done = bisect_right(self.deliveries, t)
        detail = UNKNOWN  # known from the exchange snapshots, or a run with none
        if self.exchanges:
            k = bisect_right(self._exchange_times, t)
            detail = self.exchanges[k - 1][1] if k else 0
        elif self.results.get("kind") == "items" and self.results.get("exchanges") == 0:
            detail = 0
        measures = tuple(series[index] for series in self._series)
        return Sample(index, t, xy, carrying, done, detail, measures)


def _json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise RecordingError(f"{path}: missing (is this a run's output directory?)") from None
    except (OSError, ValueError) as exc:
        raise RecordingError(f"{path}: {exc}") from None
    if not isinstance(data, dict):
        raise RecordingError(f"{path}: expected a JSON object")
    return data


_Block = tuple[float, int, int, "int | None"]  # t, byte offset, line number, exchange count


def _index(path: Path) -> tuple[list[int], list[_Block], list[_Block]]:
    """The robots (the first sample's order), every block of rows, and the snapshots."""
    try:
        stream = path.open("rb")
    except FileNotFoundError:
        raise RecordingError(f"{path}: missing (is this a run's output directory?)") from None
    with stream:
        head = stream.readline()
        if head.rstrip(b"\r\n") != _HEADER:
            raise RecordingError(f"{path}: line 1: expected the header {_HEADER.decode()!r}")
        offset, number = len(head), 1
        robots: list[int] = []
        seen: set[int] = set()
        blocks: list[_Block] = []
        first: tuple[bytes, bytes] | None = None
        n = 0  # robots per block, once the first block has ended
        for line in stream:
            number += 1
            fields = line.split(b",", 5)
            if len(fields) != 6:
                raise RecordingError(f"{path}: line {number}: expected 6 fields, got {len(fields)}")
            if n == 0:  # still in the first block: it names the robots, in order
                robot = _int(path, number, fields[1])
                if first is None:
                    first = (fields[0], fields[4])
                    blocks.append(_block(path, number, offset, fields))
                if (fields[0], fields[4]) == first and robot not in seen:
                    robots.append(robot)
                    seen.add(robot)
                else:
                    n = len(robots)
                    blocks.append(_block(path, number, offset, fields))
            elif (number - 2) % n == 0:
                blocks.append(_block(path, number, offset, fields))
            offset += len(line)
    if robots and (number - 1) % len(robots):
        raise RecordingError(
            f"{path}: {number - 1} rows: not a whole number of samples of {len(robots)} robots"
        )
    return robots, blocks, [block for block in blocks if block[3] is not None]


def _block(path: Path, number: int, offset: int, fields: list[bytes]) -> _Block:
    exchange = fields[4].strip()
    try:
        return float(fields[0]), offset, number, int(exchange) if exchange else None
    except ValueError:
        raise RecordingError(f"{path}: line {number}: t or exchange is not a number") from None


def _int(path: Path, number: int, field: bytes) -> int:
    try:
        return int(field)
    except ValueError:
        raise RecordingError(f"{path}: line {number}: robot {field!r} is not an integer") from None


def _rows(
    path: Path, offset: int, number: int, robots: list[int]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    xy = np.empty((len(robots), 2), dtype=np.float64)
    carrying = np.zeros(len(robots), dtype=np.bool_)
    with path.open("rb") as stream:
        stream.seek(offset)
        for k, robot in enumerate(robots):
            fields = stream.readline().split(b",")
            at = number + k
            if len(fields) != 6 or _int(path, at, fields[1]) != robot:
                raise RecordingError(f"{path}: line {at}: expected robot {robot}'s row")
            try:
                xy[k] = float(fields[2]), float(fields[3])
            except ValueError:
                raise RecordingError(f"{path}: line {at}: x or y is not a number") from None
            carrying[k] = fields[5].strip() == b"1"
    return xy, carrying
