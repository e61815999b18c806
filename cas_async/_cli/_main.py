"""``python -m cas_async COMMAND``: the command line, one module per command.

``run`` and ``world`` (:mod:`._run`), ``worker`` (:mod:`._worker`), ``sweep``
(:mod:`._sweep`), ``view`` (:mod:`._view`) and ``export`` (:mod:`._export`); their
arguments are in :mod:`._parser`, their exit codes in :mod:`._exits`. SIGINT and
SIGTERM stop every command within a second, with exit code 130
(:mod:`._interrupts`).
"""

from __future__ import annotations

import argparse
import gc
import sys
from collections.abc import Callable, Sequence
from typing import Final, TextIO

from ._exits import leaving_at_once
from ._export import command_export
from ._interrupts import EXIT_INTERRUPTED, Interrupted, Interrupts
from ._parser import parser
from ._pipes import PipeGuard
from ._run import command_run
from ._sweep import command_sweep
from ._view import command_view
from ._worker import command_worker

__all__ = ["main"]

Command = Callable[[argparse.Namespace, TextIO, TextIO, Interrupts, bool], int]
"""A command: its arguments, stdout, stderr, the signals, and whether the process is its own."""

COMMANDS: Final[dict[str, Command]] = {
    "run": command_run,
    "world": command_run,
    "worker": lambda args, stdout, stderr, interrupts, owns: command_worker(args, stderr),
    "sweep": command_sweep,
    "view": lambda args, stdout, stderr, interrupts, owns: command_view(
        args, stdout, stderr, interrupts
    ),
    "export": lambda args, stdout, stderr, interrupts, owns: command_export(args, stdout, stderr),
}


def main(
    argv: Sequence[str] | None = None,
    *,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
    owns_process: bool = False,
) -> int:
    """Runs the command line; returns the exit code.

    SIGINT and SIGTERM (main thread only) stop it within a second, whatever it is
    doing, with exit code 130 (see :mod:`cas_async._cli._interrupts`).

    Args:
        argv: the arguments (default: ``sys.argv[1:]``).
        stdout: where the summary goes (default: ``sys.stdout``).
        stderr: where progress and errors go (default: ``sys.stderr``).
        owns_process: the process is this command's (``python -m cas_async``): an
            interrupted run then exits as soon as its results are written, without
            stopping its robots one by one, and the collector leaves the run's
            objects alone from the end of the run on.
    """
    # A reader that goes away (| head) leaves the run to finish quietly: see _pipes.
    stdout = PipeGuard.around(stdout or sys.stdout)
    stderr = PipeGuard.around(stderr or sys.stderr)
    interrupts = Interrupts()
    try:
        interrupts.install()
        with leaving_at_once(interrupts, owns_process, (stdout, stderr)):  # nothing began
            args = parser().parse_args(argv)  # argparse requires a command, one of these
            return COMMANDS[args.command](args, stdout, stderr, interrupts, owns_process)
    except Interrupted:
        return EXIT_INTERRUPTED
    finally:
        interrupts.restore()
        if owns_process:  # what is left is freed at exit: no collection need look at it
            gc.freeze()
