"""What the live tests share: the command line as a subprocess, the trace read back, a client."""

from __future__ import annotations

import asyncio
import csv
import json
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from cas_async.live import Frame, decode_frame

ROOT: Final = Path(__file__).resolve().parents[2]
FIRE: Final = ROOT / "apps" / "fire_brigade" / "scenarios"
BOXES: Final = ROOT / "apps" / "box_moving" / "scenarios"
LIMIT: Final = 120.0
"""Wall seconds any command here may take; only a hung one comes near."""
_ENV: Final = {**os.environ, "PYTHONIOENCODING": "utf-8"}
_URL: Final = re.compile(r"(http://[^/\s]+/)")


@contextmanager
def cli(
    *args: str | os.PathLike[str], env: dict[str, str] | None = None
) -> Iterator[subprocess.Popen[str]]:
    """``python -m cas_async *args`` in the repository root; killed on leaving if still running.

    ``env`` adds to (or replaces in) this process's environment.
    """
    process = subprocess.Popen(
        [sys.executable, "-m", "cas_async", *map(str, args)],
        cwd=ROOT,
        env={**_ENV, **(env or {})},
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        encoding="utf-8",
    )
    try:
        yield process
    finally:
        process.kill()
        process.communicate(timeout=LIMIT)


def url_of(process: subprocess.Popen[str], prefix: str) -> str:
    """The address the command printed on the line starting with ``prefix``."""
    assert process.stdout is not None
    deadline = time.monotonic() + LIMIT
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            break
        if line.startswith(prefix):
            match = _URL.search(line)
            assert match, line
            return match.group(1)
    raise AssertionError(f"no {prefix!r} line; exit {process.poll()}")


def finish(process: subprocess.Popen[str]) -> tuple[int, str, str]:
    """Waits for the command's end: its exit code, the rest of stdout, stderr."""
    stdout, stderr = process.communicate(timeout=LIMIT)
    return process.returncode, stdout, stderr


@dataclass
class Watched:
    """What a client received over one connection, in order."""

    hello: dict[str, Any] = field(default_factory=dict)
    frames: list[Frame] = field(default_factory=list)
    texts: list[dict[str, Any]] = field(default_factory=list)

    @property
    def events(self) -> list[dict[str, Any]]:
        return [
            event for text in self.texts if text["type"] == "events" for event in text["events"]
        ]

    @property
    def end(self) -> dict[str, Any] | None:
        ends = [text for text in self.texts if text["type"] == "end"]
        return ends[-1] if ends else None


async def watch(url: str, limit: float = LIMIT) -> Watched:
    """Connects to the view at ``url`` and reads every message until the server closes."""
    import websockets

    seen = Watched()
    address = url.replace("http://", "ws://") + "ws"
    async with asyncio.timeout(limit), websockets.connect(address, max_size=None) as socket:
        async for message in socket:
            if isinstance(message, bytes):
                seen.frames.append(decode_frame(message))
            else:
                data = json.loads(message)
                if data["type"] == "hello":
                    seen.hello = data
                else:
                    seen.texts.append(data)
    return seen


@dataclass(frozen=True)
class TraceRows:
    """``trace.csv`` read back: each regular sample's positions and carriers, by time."""

    robots: list[int]
    times: list[float]
    xy: list[npt.NDArray[np.float64]]
    carrying: list[npt.NDArray[np.bool_]]

    def at(self, t: float) -> int:
        return self.times.index(t)


def read_trace(path: Path) -> TraceRows:
    by_time: dict[float, list[list[str]]] = {}
    with path.open(newline="", encoding="utf-8") as stream:
        reader = csv.reader(stream)
        next(reader)
        for row in reader:
            if not row[4]:  # a regular sample, not an exchange snapshot
                by_time.setdefault(float(row[0]), []).append(row)
    times = list(by_time)
    robots = [int(row[1]) for row in by_time[times[0]]]
    xy = [np.array([[float(r[2]), float(r[3])] for r in by_time[t]]) for t in times]
    carrying = [np.array([r[5] == "1" for r in by_time[t]]) for t in times]
    return TraceRows(robots, times, xy, carrying)


def results_of(out: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((out / "results.json").read_text(encoding="utf-8"))
    return data


def same_run(first: dict[str, Any], second: dict[str, Any]) -> None:
    """Two results of one virtual run: equal but for the wall time and the barrier's counts."""
    left, right = dict(first), dict(second)
    for key in ("wall_time",):
        left.pop(key), right.pop(key)
    for data in (left, right):
        data.get("statistics", {}).pop("wall_time", None)
    assert left == right
