"""Output into a pipe whose reader went away: ``python -m cas_async run ... | head -3``.

Once ``head`` has its lines it exits, and the next write to the pipe fails with
``BrokenPipeError``. That must not end the run with a traceback (nor before the
results are written): the command line writes through a :class:`PipeGuard`,
which drops what nobody reads from then on and goes on quietly. The stream's
file descriptor is pointed at ``os.devnull`` too, so the interpreter's own last
flush at exit finds nothing to complain about.
"""

from __future__ import annotations

import contextlib
import io
import os
from typing import TextIO, cast, final

__all__ = ["PipeGuard"]


@final
class PipeGuard(io.TextIOBase):
    """A text stream that writes to ``stream`` until its reader goes, then to nowhere.

    Args:
        stream: where to write (``sys.stdout``, a file, a ``StringIO``).
    """

    def __init__(self, stream: TextIO) -> None:
        super().__init__()
        self._stream = stream
        self.broken = False
        """Whether the reader went away: what is written since goes nowhere."""

    @classmethod
    def around(cls, stream: TextIO) -> TextIO:
        """``stream`` guarded (as a ``TextIO``); a guard is returned as it is."""
        return stream if isinstance(stream, cls) else cast(TextIO, cls(stream))

    def write(self, text: str) -> int:
        """Writes ``text``, or drops it once the reader has gone; returns its length."""
        if not self.broken:
            try:
                self._stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        """Flushes the stream, unless the reader has gone."""
        if not self.broken:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._gone()

    def isatty(self) -> bool:
        """Whether the stream is a terminal (``False`` once the reader has gone)."""
        return not self.broken and self._stream.isatty()

    def writable(self) -> bool:
        """Always: a guarded stream takes every write."""
        return True

    def _gone(self) -> None:
        """The reader went away: from now on writes go nowhere, the file descriptor too."""
        self.broken = True
        with contextlib.suppress(OSError, ValueError, io.UnsupportedOperation):
            fd = self._stream.fileno()
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, fd)  # what the stream still buffers drains there
            finally:
                os.close(devnull)
