"""Files written whole or not at all: a temporary file beside the target, renamed when done.

Readers see the previous file or the whole new one; an interrupted write leaves
nothing behind, and a process that ends at once (``os._exit``) removes its
temporary files first (:func:`remove_partial_files`).
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, BinaryIO, TextIO, cast

__all__ = ["AtomicFile", "atomic_binary_file", "atomic_text_file", "remove_partial_files"]


class AtomicFile:
    """A file written under a temporary name, that becomes ``path`` only when committed.

    The temporary file sits next to ``path`` (``.name.XXXX.tmp``), so the final
    rename is atomic: readers see the previous file or the whole new one, and a
    write that is interrupted or :meth:`discard`-ed leaves nothing behind.
    The file gets the usual mode (0666 less the umask), like any file a program writes.

    Args:
        path: the file to write.
        binary: a binary stream instead of UTF-8 text.
    """

    def __init__(self, path: Path, *, binary: bool = False) -> None:
        self.path = Path(path)
        fd, self._temp = tempfile.mkstemp(
            dir=self.path.parent, prefix=f".{self.path.name}.", suffix=".tmp"
        )
        _in_progress.add(self._temp)
        try:
            umask = os.umask(0)  # mkstemp makes it private (0600)
            os.umask(umask)
            os.chmod(fd, 0o666 & ~umask)
            self.stream: IO[Any] = (
                os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="")
            )
        except BaseException:
            os.close(fd)
            self.discard()
            raise

    def commit(self) -> Path:
        """Flushes the file to disk and puts it in place; returns its path."""
        try:
            self.stream.flush()
            os.fsync(self.stream.fileno())
            self.stream.close()
            os.replace(self._temp, self.path)
        except BaseException:
            self.discard()
            raise
        _in_progress.discard(self._temp)
        return self.path

    def discard(self) -> None:
        """Drops what was written; ``path`` stays as it was. Idempotent."""
        stream = getattr(self, "stream", None)
        if stream is not None:
            with contextlib.suppress(OSError):
                stream.close()
        Path(self._temp).unlink(missing_ok=True)
        _in_progress.discard(self._temp)


@contextmanager
def atomic_text_file(path: Path) -> Iterator[TextIO]:
    """A UTF-8 text stream that becomes ``path`` only if the ``with`` body completes."""
    with _atomic(path, binary=False) as stream:
        yield cast(TextIO, stream)


@contextmanager
def atomic_binary_file(path: Path) -> Iterator[BinaryIO]:
    """A binary stream that becomes ``path`` only if the ``with`` body completes."""
    with _atomic(path, binary=True) as stream:
        yield cast(BinaryIO, stream)


@contextmanager
def _atomic(path: Path, *, binary: bool) -> Iterator[IO[Any]]:
    file = AtomicFile(path, binary=binary)
    try:
        yield file.stream
    except BaseException:  # also on Ctrl-C: the temp file must not outlive the write
        file.discard()
        raise
    file.commit()


_in_progress: set[str] = set()  # temporary files of the atomic writes under way


def remove_partial_files() -> None:
    """Removes the temporary files of atomic writes still under way, for a process about to end.

    A process that ends at once (``os._exit``) runs no ``finally``: it calls this
    first, so that no half-written temporary file is left next to the results.
    """
    for name in list(_in_progress):
        Path(name).unlink(missing_ok=True)
