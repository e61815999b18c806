r"""Live progress of a scenario run: a redrawn bar on a terminal, plain lines in a log.

On a TTY one line is redrawn in place (``\r``) at most ten times per wall second::

    [#########-----------]  9/20 buckets | t = 112.5 s | 31 exchanges

Elsewhere (a pipe, a file, CI) one plain line is printed every ``interval`` wall
seconds, with no control characters::

    t=112.5s buckets 9/20 exchanges 31

What is counted is the mission's (its objective's ``noun`` and ``detail``):
``objects 3/5 | ... | 2 joint carries`` for another application.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Final, TextIO, final

from ._report import plural

__all__ = ["Progress"]

_TTY_PERIOD: Final = 0.1
"""Wall seconds between redraws on a TTY: faster only burns the terminal."""
_BAR_WIDTH: Final = 20


@final
class Progress:
    """Shows how far a run is, throttled by wall time.

    :meth:`update` may be called thousands of times per second: it stores the
    state and reads the clock, and formats only when a line is due. The first
    update is shown at once. After :meth:`close`, updates are ignored.

    Args:
        stream: where to write (e.g. ``sys.stderr``).
        target: items to deliver for the run to be complete.
        item_name: what an item is called, singular (e.g. ``"bucket"``).
        interval: wall seconds between plain lines (not on a TTY).
        detail: what the second count counts, plural (``"exchanges"``).
        tty: redraw in place; ``None`` asks ``stream.isatty()``.
        now: the wall clock, in seconds.

    Raises:
        ValueError: ``target`` is negative or ``interval`` not a positive number.
    """

    __slots__ = (
        "_closed",
        "_delivered",
        "_detail",
        "_due",
        "_exchanges",
        "_items",
        "_now",
        "_period",
        "_shown_width",
        "_sim_time",
        "_stream",
        "_target",
        "_tty",
    )

    def __init__(
        self,
        stream: TextIO,
        *,
        target: int,
        item_name: str,
        interval: float = 1.0,
        tty: bool | None = None,
        now: Callable[[], float] = time.monotonic,
        detail: str = "exchanges",
    ) -> None:
        if target < 0:
            raise ValueError(f"Progress: target must not be negative, got {target}")
        if not (interval > 0 and math.isfinite(interval)):
            raise ValueError(f"Progress: interval must be a positive number, got {interval!r}")
        self._stream = stream
        self._target = int(target)
        self._items = plural(item_name)
        self._detail = detail
        self._tty = stream.isatty() if tty is None else tty
        self._period = _TTY_PERIOD if self._tty else float(interval)
        self._now = now
        self._due = -math.inf
        self._sim_time = 0.0
        self._delivered = 0
        self._exchanges = 0
        self._shown_width = 0  # characters of the line on screen, to blank a longer old one
        self._closed = False

    def update(self, sim_time: float, delivered: int, exchanges: int) -> None:
        """Records the run's state and shows it if a line is due.

        ``delivered`` counts toward the target; ``exchanges`` is the second count
        (named by ``detail``).
        """
        if self._closed:
            return
        self._sim_time = sim_time
        self._delivered = delivered
        self._exchanges = exchanges
        now = self._now()
        if now < self._due:
            return
        self._due = now + self._period
        self._show()

    def close(self, final: bool = True) -> None:
        """Ends the display; later calls do nothing.

        Args:
            final: show the last recorded state (a TTY's line is redrawn, a plain
                line is printed). With ``False`` only a TTY's line is ended, so
                what follows (e.g. an error) starts on a fresh line.
        """
        if self._closed:
            return
        self._closed = True
        if final:
            self._show()
        if self._tty and self._shown_width:
            self._stream.write("\n")
            self._stream.flush()

    def _show(self) -> None:
        if self._tty:
            line = self._bar_line()
            # spaces, not an erase sequence, blank what a longer previous line left
            padding = " " * max(0, self._shown_width - len(line))
            self._stream.write(f"\r{line}{padding}")
            self._shown_width = len(line)
        else:
            self._stream.write(
                f"t={self._sim_time:.1f}s {self._items} {self._delivered}/{self._target}"
                f" {self._detail} {self._exchanges}\n"
            )
        self._stream.flush()

    def _bar_line(self) -> str:
        if self._target:
            filled = min(_BAR_WIDTH, max(0, self._delivered) * _BAR_WIDTH // self._target)
        else:
            filled = _BAR_WIDTH
        bar = "#" * filled + "-" * (_BAR_WIDTH - filled)
        digits = len(str(self._target))
        return (
            f"[{bar}] {self._delivered:>{digits}}/{self._target} {self._items}"
            f" | t = {self._sim_time:.1f} s | {self._exchanges} {self._detail}"
        )
