"""``sweep SCENARIO.toml --seeds N [--vary KEY=A,B,...]...``: a scenario over a grid.

It runs the scenario for seeds 1..N at every point of the grid of the ``--vary``
values, in worker processes (``--jobs``) or on the workers of a Dask scheduler
(``--cluster``, the ``dask`` extra), on virtual time unless ``--set
run.virtual=false`` (allowed; each run then takes wall time). Every point is
checked first (exit code 2 naming the file, key and point). It shows progress,
writes ``sweep.json``, ``runs.csv`` (a row as each run finishes), ``table.md``,
``summary.json`` and ``box_<metric>.png``, and prints the table (see
:mod:`cas_async.scenario.sweeps`). ``--resume`` runs only what ``--out`` lacks,
after checking that it holds this very sweep.

SIGINT and SIGTERM stop it within a fraction of a second: the runs not finished are
abandoned (the local workers killed, a cluster's tasks cancelled); what finished is
written (the files, not the box plots) and its table printed. A lost connection to
the cluster ends it the same way, with exit code 1. A file is always written whole
or not at all.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, TextIO, cast

from ..scenario import ScenarioError
from ..scenario.sweeps import SweepOutcome, SweepPlan, plan_sweep, run_sweep, sweep_table
from ..scenario.sweeps._box_plots import write_box_plots
from ..scenario.sweeps._files import write_sweep_files
from ..scenario.sweeps._manifest import MANIFEST, check_resume
from ._exits import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_OK, EXIT_USAGE, leaving_at_once, made
from ._interrupts import Interrupted, Interrupts

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["command_sweep"]

CONNECT_WAIT: Final = 10.0
"""Wall seconds to reach the Dask scheduler, and to close the connection."""


def command_sweep(
    args: argparse.Namespace,
    stdout: TextIO,
    stderr: TextIO,
    interrupts: Interrupts,
    owns_process: bool,
) -> int:
    # Until the runs start, a signal abandons the work in hand, as for any command.
    try:
        plan = plan_sweep(args.scenario, seeds=args.seeds, vary=args.vary, overrides=args.overrides)
    except ScenarioError as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE
    out: Path = args.out or Path("runs") / f"sweep-{plan.path.stem}"
    if args.resume:
        try:  # before a cluster is reached: a refusal costs nothing
            check_resume(out, plan)
        except ScenarioError as exc:
            print(f"error: {exc}", file=stderr)
            return EXIT_USAGE
    if not made(out, stderr):
        return EXIT_USAGE
    client = None
    if args.cluster is not None:
        client = _connect(args.cluster, stderr)
        if client is None:
            return EXIT_USAGE
    if plan.real_time:
        print("note: run.virtual=false: each run takes wall time (see time_factor)", file=stderr)
    with interrupts.deferred():  # a signal is noted, and the sweep looks ten times a second
        try:
            outcome = run_sweep(
                plan,
                jobs=args.jobs,
                executor=client,
                out=out,
                resume=args.resume,
                progress_to=stderr,
                stop=lambda: interrupts.interrupted,
            )
        finally:
            if client is not None:
                _close(client)
        written = [out / MANIFEST, *write_sweep_files(outcome, out)]
        print(sweep_table(outcome), end="", file=stdout)

    def say_written() -> None:
        print(f"wrote {', '.join(path.name for path in written)} to {out}/", file=stdout)

    if not args.no_plots and not outcome.interrupted and not interrupts.interrupted:
        # A signal abandons them; each file is written whole or not at all.
        with (
            leaving_at_once(interrupts, owns_process, (stdout, stderr), say_written),
            contextlib.suppress(Interrupted),
        ):
            written += write_box_plots(outcome, out)
    say_written()
    if interrupts.interrupted:
        if outcome.interrupted:
            print(f"interrupted: {_how_far(outcome, out)}", file=stderr)
        else:
            print("interrupted: the box plots left out", file=stderr)
        return EXIT_INTERRUPTED
    if outcome.error is not None:
        print(f"error: {outcome.error}: {_how_far(outcome, out)}", file=stderr)
        return EXIT_FAILED
    return EXIT_OK if outcome.all_completed else EXIT_FAILED


def _how_far(outcome: SweepOutcome, out: Path) -> str:
    """How far the sweep got, and how to go on: ``"17 of 40 runs done (DIR/runs.csv), ..."``."""
    plan: SweepPlan = outcome.plan
    done = len(outcome.runs)
    return (
        f"{done} of {plan.runs} runs done ({out / 'runs.csv'}), the others and the box plots "
        f"left out; the same command with --resume runs the other {plan.runs - done}"
    )


def _connect(address: str, stderr: TextIO) -> Client | None:
    """A client of the Dask scheduler at ``address``; ``None`` once it said why not."""
    try:
        import distributed
    except ImportError:
        print(
            "error: --cluster needs the dask extra (distributed): pip install 'cas_async[dask]'",
            file=stderr,
        )
        return None
    # Its client's news (a connection closed, with a traceback) is Dask's: warnings only.
    logging.getLogger("distributed").setLevel(logging.WARNING)
    connect: Any = distributed.Client  # not annotated
    try:
        # not the process's default client: dask collections elsewhere stay as they were
        return cast("Client", connect(address, timeout=CONNECT_WAIT, set_as_default=False))
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        print(f"error: --cluster {address}: no Dask scheduler reached: {exc}", file=stderr)
        return None


def _close(client: Client) -> None:
    """Closes ``client``; quietly when its connection is lost (Dask would log tracebacks)."""
    with _unlogged() if client.status != "running" else contextlib.nullcontext():
        cast(Any, client).close(timeout=CONNECT_WAIT)  # not annotated


@contextlib.contextmanager
def _unlogged() -> Iterator[None]:
    """Within the block, nothing is logged (Dask's loggers each have their own level)."""
    before = logging.root.manager.disable
    logging.disable(logging.CRITICAL)
    try:
        yield
    finally:
        logging.disable(before)
