"""``sweep SCENARIO.toml --seeds N [--vary KEY=A,B,...]...``: a scenario over a grid.

It runs the scenario for seeds 1..N at every point of the grid of the ``--vary``
values, in worker processes, on virtual time unless ``--set run.virtual=false``
(allowed; each run then takes wall time). Every point is checked first (exit code
2 naming the file, key and point). It prints a line per run, writes ``runs.csv``,
``table.md``, ``summary.json`` and ``box_<metric>.png``, and prints the table (see
:mod:`cas_async.scenario.sweeps`).

SIGINT and SIGTERM stop it within a fraction of a second: the runs not finished are
abandoned, the workers killed; what finished is written (the files, not the box
plots) and its table printed. A file is always written whole or not at all.
"""

from __future__ import annotations

import argparse
import contextlib
from pathlib import Path
from typing import TextIO

from ..scenario import ScenarioError
from ..scenario.sweeps import plan_sweep, run_sweep, sweep_table
from ..scenario.sweeps._box_plots import write_box_plots
from ..scenario.sweeps._files import write_sweep_files
from ._exits import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE, leaving_at_once, made
from ._interrupts import Interrupted, Interrupts

__all__ = ["command_sweep"]


def command_sweep(
    args: argparse.Namespace,
    stdout: TextIO,
    stderr: TextIO,
    interrupts: Interrupts,
    owns_process: bool,
) -> int:
    try:  # a signal meanwhile abandons it, as any other work done before the runs
        plan = plan_sweep(args.scenario, seeds=args.seeds, vary=args.vary, overrides=args.overrides)
    except ScenarioError as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE
    out: Path = args.out or Path("runs") / f"sweep-{plan.path.stem}"
    if not made(out, stderr):
        return EXIT_USAGE
    if plan.real_time:
        print("note: run.virtual=false: each run takes wall time (see time_factor)", file=stderr)
    with interrupts.deferred():  # a signal is noted, and the sweep looks ten times a second
        outcome = run_sweep(
            plan, jobs=args.jobs, progress_to=stderr, stop=lambda: interrupts.interrupted
        )
        written = write_sweep_files(outcome, out)
        print(sweep_table(outcome), end="", file=stdout)

    def say_written() -> None:
        print(f"wrote {', '.join(path.name for path in written)} to {out}/", file=stdout)

    if not args.no_plots and not interrupts.interrupted:
        # A signal abandons them; each file is written whole or not at all.
        with (
            leaving_at_once(interrupts, owns_process, (stdout, stderr), say_written),
            contextlib.suppress(Interrupted),
        ):
            written += write_box_plots(outcome, out)
    say_written()
    if interrupts.interrupted:
        left_out = "the runs not finished and the box plots" if outcome.interrupted else "box plots"
        print(f"interrupted: {left_out} left out", file=stderr)
        return EXIT_INTERRUPTED
    return EXIT_OK if outcome.all_completed else EXIT_FAILED
