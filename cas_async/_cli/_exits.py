"""How a command ends: its exit codes, and leaving at once when a signal comes.

Exit codes: 0 the mission completed (``sweep``: every run did); 1 it failed or ran
out of simulated time (``sweep``: some run did, or the sweep ended early: its
cluster lost, its executor broken); 2 the command line, the scenario or the set-up
is wrong: anything refused before the robots run, on one line ``error: ...``; 130
interrupted.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Final, NoReturn, TextIO

from ..scenario import RunStatus
from ..scenario.output._atomic_files import remove_partial_files
from ._interrupts import EXIT_INTERRUPTED, Interrupts

__all__ = [
    "EXIT_FAILED",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_USAGE",
    "STATUS_EXIT",
    "exit_process",
    "leaving_at_once",
    "made",
]

EXIT_OK: Final = 0
EXIT_FAILED: Final = 1
EXIT_USAGE: Final = 2

STATUS_EXIT: Final = {
    RunStatus.COMPLETED: EXIT_OK,
    RunStatus.FAILED: EXIT_FAILED,
    RunStatus.STOPPED: EXIT_FAILED,
    RunStatus.TIMED_OUT: EXIT_FAILED,
    RunStatus.INTERRUPTED: EXIT_INTERRUPTED,
}
"""The exit code of a run that ended so."""


def made(out: Path, stderr: TextIO) -> bool:
    """Makes ``--out`` before anything runs (a long run must not end in "cannot write")."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"error: --out {out}: {exc.strerror or exc}", file=stderr)
        return False
    return True


def leaving_at_once(
    interrupts: Interrupts,
    owns_process: bool,
    streams: tuple[TextIO, TextIO],
    last_words: Callable[[], None] | None = None,
) -> contextlib.AbstractContextManager[None]:
    """Within the block a signal ends the process at once, when the process is ours.

    Raising :class:`Interrupted` from the handler is not enough there: an exception
    raised while a finalizer runs (the collector calls them at any moment) is
    printed and dropped. Elsewhere the signal raises, best effort.
    """
    if not owns_process:
        return contextlib.nullcontext()
    return interrupts.calling(lambda: exit_process(streams, last_words))


def exit_process(
    streams: tuple[TextIO, TextIO], last_words: Callable[[], None] | None = None
) -> NoReturn:
    """Calls ``last_words``, removes half-written files, flushes, and exits 130 at once."""
    stdout, stderr = streams
    with contextlib.suppress(Exception):
        if last_words is not None:
            last_words()
    with contextlib.suppress(Exception):
        remove_partial_files()
    for stream in (stdout, stderr, sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(EXIT_INTERRUPTED)
