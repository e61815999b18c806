"""A run directory's files read as untrusted input: whatever they hold, one clear error.

A run directory may come from anywhere (a colleague's upload, an archive): ``view``
and ``export`` read it as a server reads a request. A file is read only if it is a
regular file inside the directory (no FIFO, which would block; no device, which
would never end; no link out of the directory) and not larger than its limit; a
line of ``trace.csv`` is at most :data:`LINE_LIMIT` bytes; JSON that nests deeper
than the parser allows is refused; every field is checked for its type and range
(:class:`Fields`). Anything else is a :class:`RecordingError` naming the file, the
line and the field::

    RUN/trace.csv: line 27: t: expected a number from 0 to 1e+09, got 'nan'
    RUN/results.json: groups: expected an object of robot-id lists, got a list
    RUN/trace.csv: not a regular file (a FIFO)
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any, Final, final

from .. import CasError

__all__ = [
    "ID_LIMIT",
    "LINE_LIMIT",
    "POSITION_LIMIT",
    "RESULTS_LIMIT",
    "SCENE_LIMIT",
    "TIME_LIMIT",
    "TRACE_LIMIT",
    "Fields",
    "RecordingError",
    "open_regular",
    "read_json",
    "show",
]

RESULTS_LIMIT: Final = 64 * 1024 * 1024
"""Bytes of ``results.json``, at most."""
SCENE_LIMIT: Final = 16 * 1024 * 1024
"""Bytes of ``scene.json``, at most."""
TRACE_LIMIT: Final = 64 * 1024**3
"""Bytes of ``trace.csv``, at most (it is read a line at a time)."""
LINE_LIMIT: Final = 4096
"""Bytes of a line of ``trace.csv``, at most (a row is a few dozen)."""
TIME_LIMIT: Final = 1e9
"""Simulated seconds a recording may reach (a bag's stamps count seconds in an int32)."""
POSITION_LIMIT: Final = 1e12
"""World units a position may be from the origin, at most."""
ID_LIMIT: Final = 2**53
"""Robot ids are integers below this in magnitude (a browser reads them exactly)."""

_KINDS: Final = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


class RecordingError(CasError, ValueError):
    """A run directory cannot be replayed: names the file, and the line or key at fault."""


def show(value: object) -> str:
    """A value as an error message quotes it: short, and its type when that is the point."""
    if isinstance(value, str | bytes):
        text = value.decode("utf-8", "replace") if isinstance(value, bytes) else value
        return repr(text[:40] + ("..." if len(text) > 40 else ""))
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        text = repr(value)
        return text if len(text) <= 40 else f"a number of {len(text)} digits"
    if isinstance(value, list):
        return "a list"
    return "an object" if isinstance(value, dict) else type(value).__name__


@contextlib.contextmanager
def open_regular(path: Path, run_dir: Path, limit: int) -> Iterator[IO[bytes]]:
    """``path`` opened for reading, if it is a regular file of the run, of at most ``limit`` bytes.

    Raises:
        FileNotFoundError: there is no such file (the caller says what is missing).
        RecordingError: it is no regular file (a FIFO, a device, a directory), a link
            out of ``run_dir``, larger than ``limit``, or cannot be opened.
    """
    if path.is_symlink():
        target = Path(os.path.realpath(path))
        if not target.is_relative_to(Path(os.path.realpath(run_dir))):
            raise RecordingError(f"{path}: a link out of the run directory (to {target})")
        path = target
    try:  # non-blocking: opening a FIFO for reading would wait for a writer
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW | os.O_CLOEXEC)
    except FileNotFoundError:
        raise
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise RecordingError(f"{path}: a link out of the run directory") from None
        raise RecordingError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    try:
        status = os.fstat(fd)
        for test, kind in _KINDS:
            if test(status.st_mode):
                raise RecordingError(f"{path}: not a regular file ({kind})")
        if not stat.S_ISREG(status.st_mode):
            raise RecordingError(f"{path}: not a regular file")
        if status.st_size > limit:
            raise RecordingError(
                f"{path}: {status.st_size:,} bytes, more than a run writes ({limit:,} at most)"
            )
        os.set_blocking(fd, True)
        stream = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    with stream:
        yield stream


def read_json(path: Path, run_dir: Path, limit: int) -> dict[str, Any]:
    """A JSON object from a file of the run (see :func:`open_regular`).

    Raises:
        FileNotFoundError: there is no such file.
        RecordingError: it cannot be read, is no JSON object, or nests too deep.
    """
    with open_regular(path, run_dir, limit) as stream:
        data = stream.read(limit + 1)
    try:
        value = json.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise RecordingError(f"{path}: not UTF-8 (byte {exc.start})") from None
    except RecursionError:
        raise RecordingError(f"{path}: nested deeper than a run writes") from None
    except ValueError as exc:
        raise RecordingError(f"{path}: not JSON: {exc}") from None
    if not isinstance(value, dict):
        raise RecordingError(f"{path}: expected a JSON object, got {show(value)}")
    return value


@final
class Fields:
    """The fields of one JSON object of a file, checked as they are read.

    Each method returns the field's value, or its default when the field is absent
    (``None`` given as the default), and raises :class:`RecordingError` naming the
    file and the field when it is present but wrong.

    Args:
        path: the file, for the messages.
        data: the object.
        where: the object's own key path in the file (``"config.world"``), or ``""``.
    """

    def __init__(self, path: Path, data: dict[str, Any], where: str = "") -> None:
        self._path = path
        self._data = data
        self._where = where

    def _name(self, key: str) -> str:
        return f"{self._where}.{key}" if self._where else key

    def wrong(self, key: str, expected: str, value: object) -> RecordingError:
        """The error for ``key``: what was expected, what came."""
        return RecordingError(
            f"{self._path}: {self._name(key)}: expected {expected}, got {show(value)}"
        )

    def has(self, key: str) -> bool:
        """Whether the field is there (and not ``null``)."""
        return self._data.get(key) is not None

    def text(self, key: str, default: str = "") -> str:
        """A string."""
        value = self._data.get(key, default)
        if not isinstance(value, str):
            raise self.wrong(key, "a string", value)
        return value

    def integer(self, key: str, default: int = 0) -> int:
        """An integer from 0, below :data:`ID_LIMIT` (``true`` is no integer)."""
        value = self._data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < ID_LIMIT:
            raise self.wrong(key, "an integer from 0 to 2**53", value)
        return value

    def number(
        self, key: str, default: float | None = 0.0, *, low: float = 0.0, high: float = TIME_LIMIT
    ) -> float | None:
        """A number from ``low`` to ``high`` (``None`` when absent or ``null`` and allowed)."""
        value = self._data.get(key, default)
        if value is None and default is None:
            return None
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not low <= value <= high  # NaN fails too
        ):
            raise self.wrong(key, f"a number from {low:g} to {high:g}", value)
        return float(value)

    def times(self, key: str) -> list[float]:
        """A list of instants, each from 0 to :data:`TIME_LIMIT`, in order."""
        value = self._data.get(key)
        if not isinstance(value, list):
            raise self.wrong(key, "a list of instants", value)
        times: list[float] = []
        for index, t in enumerate(value):
            if isinstance(t, bool) or not isinstance(t, int | float) or not 0 <= t <= TIME_LIMIT:
                raise self.wrong(f"{key}[{index}]", f"a number from 0 to {TIME_LIMIT:g}", t)
            if times and t < times[-1]:
                raise self.wrong(f"{key}[{index}]", f"an instant not before {times[-1]!r}", t)
            times.append(float(t))
        return times

    def table(self, key: str) -> Fields:
        """A nested object (an empty one when absent)."""
        value = self._data.get(key, {})
        if not isinstance(value, dict):
            raise self.wrong(key, "an object", value)
        return Fields(self._path, value, self._name(key))

    def groups(self, key: str) -> dict[str, list[int]]:
        """An object of lists of robot ids, by group name (an empty one when absent)."""
        value = self._data.get(key, {})
        if not isinstance(value, dict):
            raise self.wrong(key, "an object of robot-id lists", value)
        groups: dict[str, list[int]] = {}
        for name, ids in value.items():
            if not isinstance(ids, list):
                raise self.wrong(f"{key}.{name}", "a list of robot ids", ids)
            for index, robot in enumerate(ids):
                if isinstance(robot, bool) or not isinstance(robot, int) or abs(robot) >= ID_LIMIT:
                    raise self.wrong(f"{key}.{name}[{index}]", "a robot id (an integer)", robot)
            groups[name] = list(ids)
        return groups

    def series(self, key: str, samples: int) -> dict[str, list[float]]:
        """Each measure's values, one per sample (NaN unknown), by measure name.

        A measure with no list of one value per sample is not shown (all NaN): a
        run may stop sampling a measure; values that are not numbers are refused.
        """
        value = self._data.get(key)
        if not isinstance(value, dict):
            raise self.wrong(key, "an object of measures", value)
        series: dict[str, list[float]] = {}
        for name, measure in value.items():
            values = measure.get("value") if isinstance(measure, dict) else None
            if not isinstance(values, list) or len(values) != samples:
                series[name] = [math.nan] * samples
                continue
            read: list[float] = []
            for index, item in enumerate(values):
                if item is None:
                    read.append(math.nan)
                elif isinstance(item, bool) or not isinstance(item, int | float):
                    raise self.wrong(f"{key}.{name}.value[{index}]", "a number or null", item)
                else:
                    try:
                        read.append(float(item))
                    except OverflowError:  # an integer past a float's range
                        raise self.wrong(
                            f"{key}.{name}.value[{index}]", "a number or null", item
                        ) from None
            series[name] = read
        return series
