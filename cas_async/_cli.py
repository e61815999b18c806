"""``python -m cas_async``: the command line.

``run SCENARIO.toml`` loads and validates the scenario (exit code 2 when it is
wrong, before anything starts), runs it with a live progress line, prints the
summary table, and writes ``results.json``, ``trace.csv`` and the PNG figures to
the output directory.

``sweep SCENARIO.toml --seeds N [--vary KEY=A,B,...]...`` runs it for seeds 1..N
at every point of the grid of the ``--vary`` values, in worker processes, on
virtual time unless ``--set run.virtual=false`` (allowed; each run then takes wall
time). Every point is checked first (exit code 2 naming the file, key and point).
It prints a line per run, writes ``runs.csv``, ``table.md``, ``summary.json`` and
``box_<metric>.png``, and prints the table (see :mod:`cas_async.scenario._sweep`).

SIGINT and SIGTERM stop ``run`` within a second at any moment. While the
scenario loads, nothing is written; while the robots are built, ``results.json``
says the run was interrupted before anything ran. Once the robots run,
what was measured is written first (``results.json``; ``trace.csv`` is written as
the run goes, so little is left); as ``python -m cas_async`` the process then
exits at once, leaving the robots and their sockets to the OS, without the figures.
They stop ``sweep`` within a fraction of a second: the runs not finished are
abandoned, the workers killed; what finished is written (the files, not the
box plots) and its table printed. A file is always written whole or not at all.

Exit codes: 0 the mission completed (``sweep``: every run did); 1 it failed or ran
out of simulated time (``sweep``: some run did); 2 the command line, the scenario
or the set-up is wrong: anything refused before the robots run, on one line
``error: ...`` (the app's build refusing, ``--processes`` without the zenoh extra
or with an objective that cannot run across processes, a start refused by a
transport or a clock; ``results.json`` says so too); 130 interrupted. A run across
processes whose workers do not come, or go during the start, fails on one line
too, with exit code 1 and ``results.json``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import gc
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Final, NoReturn, TextIO, final

from . import _cli_view as views
from ._cli_parser import overrides_of, parser
from ._errors import ConfigurationError
from ._interrupts import EXIT_INTERRUPTED, Interrupted, Interrupts
from ._pipes import PipeGuard
from ._runner import run
from ._swarm_key import SwarmKey
from .live import write_scene
from .scenario import (
    FailOnDrops,
    RunResult,
    RunStatus,
    Scenario,
    ScenarioError,
    ScenarioRun,
    check_key,
    load_scenario,
    plan_sweep,
    run_sweep,
    sweep_table,
)
from .scenario._atomic_files import remove_partial_files
from .scenario._processes import WorkerLost, WorkerRefused
from .scenario._report import summary_table, write_results
from .scenario._sweep_plots import write_box_plots
from .scenario._sweep_report import write_sweep_files
from .scenario._worker import run_worker
from .scenario._world import World
from .transport._zenoh import import_zenoh

__all__ = ["main"]

EXIT_OK: Final = 0
EXIT_FAILED: Final = 1
EXIT_USAGE: Final = 2

_STATUS_EXIT: Final = {
    RunStatus.COMPLETED: EXIT_OK,
    RunStatus.FAILED: EXIT_FAILED,
    RunStatus.TIMED_OUT: EXIT_FAILED,
    RunStatus.INTERRUPTED: EXIT_INTERRUPTED,
}


def _write_figures(scenario_run: ScenarioRun, scenario: Scenario, out: Path) -> list[Path]:
    from .scenario._plots import write_plots  # matplotlib is imported only here

    result = scenario_run.result
    paths = write_plots(
        scenario_run.trace,
        result.groups,
        (scenario.world.width, scenario.world.height),
        out,
        title=f"{result.app}, {scenario.path.name}, seed {result.seed}",
        exchanges_traced=scenario.run.trace_exchanges,
        snapshot_exchanges=scenario_run.mission.snapshot_exchanges,
        delivery_times=result.delivery_times,
        series=result.series,
        item_name=result.item_name,
        verb=result.verb,
    )
    return paths + scenario_run.objective.figures(scenario_run.trace, out)


def _made(out: Path, stderr: TextIO) -> bool:
    """Makes ``--out`` before anything runs (a long run must not end in "cannot write")."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"error: --out {out}: {exc.strerror or exc}", file=stderr)
        return False
    return True


def _command_run(
    args: argparse.Namespace,
    stdout: TextIO,
    stderr: TextIO,
    interrupts: Interrupts,
    owns_process: bool,
) -> int:
    try:
        scenario = load_scenario(args.scenario, overrides_of(args))
    except ScenarioError as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE
    try:
        key = SwarmKey.from_file(args.key_file) if args.key_file else SwarmKey.from_env()
        check_key(scenario, key)  # before the run, as every other refusal
    except ConfigurationError as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE
    out = args.out or Path("runs") / f"{scenario.path.stem}-seed{scenario.run.seed}"
    stop = asyncio.Event()
    started = time.perf_counter()

    def abandon_build() -> None:
        """The verdict of a run interrupted before its robots existed."""
        if out.is_dir():  # the signal may have come before it was made
            write_results(_not_built(scenario, time.perf_counter() - started), out)
            print(f"wrote results.json to {out}/", file=stdout)
        print("interrupted while building the robots: nothing ran", file=stderr)

    try:  # synchronous, before the loop starts: a signal abandons it
        with _leaving_at_once(interrupts, owns_process, (stdout, stderr), abandon_build):
            if not _made(out, stderr):
                return EXIT_USAGE
            world = _world(args, scenario, key)
            scenario_run = ScenarioRun(
                scenario,
                key=key,
                progress_to=stderr,
                stop=stop,
                trace_csv=out / "trace.csv",
                world=world,
            )
    except Interrupted:
        with interrupts.deferred():
            abandon_build()
        return EXIT_INTERRUPTED
    except ConfigurationError as exc:  # the app's build, --processes, the layers built
        print(f"error: {exc}", file=stderr)
        if out.is_dir():
            with interrupts.deferred():
                write_results(_refused(scenario, exc, time.perf_counter() - started), out)
        return EXIT_USAGE
    try:
        live = views.open_live(args, scenario, stdout)  # bound now: the robots start on the loop
    except ConfigurationError as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE
    session = _Session(
        scenario_run, scenario, out, (stdout, stderr), interrupts, owns_process, not args.no_plots
    )
    session.fail_on_drops = args.fail_on_drops
    session.live = live
    with session.leaving_at_once():
        with interrupts.calling(session.request_stop):
            run(session.drive(stop), virtual=scenario.run.virtual)
        if session.refused is not None:
            print(f"error: {session.refused}", file=stderr)
            refused = session.refused
            lost = isinstance(refused, WorkerLost) and not isinstance(refused, WorkerRefused)
            return EXIT_FAILED if lost else EXIT_USAGE
        return session.finish()


def _world(args: argparse.Namespace, scenario: Scenario, key: SwarmKey | None) -> World | None:
    """The world of a run across processes (``--processes``, ``world``), or ``None``."""
    if args.command == "world":
        return World(scenario, workers=args.workers, key=key, listen=args.listen, spawn=False)
    if getattr(args, "processes", None):
        try:
            import_zenoh()
        except ConfigurationError as exc:
            raise ConfigurationError(
                f"--processes runs the robots in worker processes that talk over Zenoh: {exc}"
            ) from None
        return World(scenario, workers=args.processes, key=key)
    return None


def _command_worker(args: argparse.Namespace, stderr: TextIO) -> int:
    try:
        key = SwarmKey.from_file(args.key_file) if args.key_file else SwarmKey.from_env()
        return run_worker(args.connect, key, listen=args.listen, quiet=args.quiet, wait=args.wait)
    except ConfigurationError as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE
    except WorkerLost as exc:  # no world answered, or it went away
        print(f"error: {exc}", file=stderr)
        return EXIT_FAILED


def _command_sweep(
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
    if not _made(out, stderr):
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
            _leaving_at_once(interrupts, owns_process, (stdout, stderr), say_written),
            contextlib.suppress(Interrupted),
        ):
            written += write_box_plots(outcome, out)
    say_written()
    if interrupts.interrupted:
        left_out = "the runs not finished and the box plots" if outcome.interrupted else "box plots"
        print(f"interrupted: {left_out} left out", file=stderr)
        return EXIT_INTERRUPTED
    return EXIT_OK if outcome.all_completed else EXIT_FAILED


@final
class _Session:
    """One ``run`` command from the moment its robots are built: running, writing, exiting.

    Results are written as soon as the run ends, before the robots stop (for ten
    thousand robots, stopping takes most of a second), and again once they have:
    stopping may find a failure. Then the figures. An interrupted run whose process
    is this command's exits once its results are written, leaving the robots (and
    their sockets) to the OS.
    """

    def __init__(
        self,
        scenario_run: ScenarioRun,
        scenario: Scenario,
        out: Path,
        streams: tuple[TextIO, TextIO],
        interrupts: Interrupts,
        owns_process: bool,
        plots: bool,
    ) -> None:
        self._run = scenario_run
        self._scenario = scenario
        self._out = out
        self._stdout, self._stderr = streams
        self._interrupts = interrupts
        self._owns_process = owns_process
        self._plots = plots
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._written: list[Path] = []
        self._failure_shown = False  # a traceback printed with the summary
        self.refused: ConfigurationError | WorkerLost | None = None
        """Why the robots could not start: a configuration error, or a lost process."""
        self.fail_on_drops: FailOnDrops | None = None
        """The drops that fail the run (``--fail-on-drops``), if any do."""
        self.live: views.LiveOptions | None = None
        """``--live``: the run's view is served while it runs."""

    def request_stop(self) -> None:
        """A signal while the loop runs (called from the signal handler).

        The loop is asked to stop the run at its next pass. When the process is
        this command's, that pass ends the run there and then (see
        :meth:`_stop_now`): waiting for the run's own tasks to notice would take
        several passes, each a fraction of a second with thousands of robots.
        """
        loop, stop = self._loop, self._stop
        if loop is None or stop is None:
            return  # the loop is not running yet: drive() sees interrupts.received
        with contextlib.suppress(RuntimeError):  # the loop has closed: finish() sees it
            loop.call_soon_threadsafe(self._stop_now if self._owns_process else stop.set)

    async def drive(self, stop: asyncio.Event) -> None:
        """Starts, runs and stops the robots; writes the results as soon as the run ends."""
        self._loop, self._stop = asyncio.get_running_loop(), stop
        if self._interrupts.interrupted:
            stop.set()
        async with contextlib.AsyncExitStack() as stack:
            await stack.enter_async_context(
                views.serve_live(self.live, self._run, stop, self._stderr)
            )
            try:
                await stack.enter_async_context(self._run)
            except (ConfigurationError, WorkerLost) as exc:  # refused while starting
                self.refused = exc
                with self._interrupts.deferred():
                    write_results(self._run.failed_to_start(exc), self._out)
                return
            self._ended(await self._run.until_done())
            if self._interrupts.interrupted and self._owns_process:
                self._exit_now()

    def _stop_now(self) -> None:
        """A loop callback, in a process of our own: ends the run, writes, exits 130."""
        if not self._written:
            self._ended(self._run.interrupt())
        self._exit_now()

    def _ended(self, result: RunResult) -> None:
        """Writes results.json and trace.csv, prints the summary (a signal waits for them)."""
        if self._written:
            return
        if self._owns_process:
            # The run's objects live until the process ends: the collector need not
            # look at them again (a full collection of 10,000 robots takes a second,
            # and the interpreter's exit seconds).
            gc.freeze()
        if self.fail_on_drops is not None:
            self.fail_on_drops.judge(result)
        with self._interrupts.deferred():
            self._written = [write_results(result, self._out)]
            if self._run.trace_csv is not None:  # written as the run went
                self._written.append(self._run.trace_csv)
            self._written.append(write_scene(self._run, self._out))  # what a replay draws
            print(summary_table(result), file=self._stdout)
            if result.traceback:
                print(result.traceback, file=self._stderr)
                self._failure_shown = True

    def finish(self) -> int:
        """After the robots stopped: what stopping found, the figures; returns the exit code."""
        result = self._run.result
        interrupts = self._interrupts
        with interrupts.deferred():
            if result.traceback and not self._failure_shown:
                print(f"while stopping the robots:\n{result.traceback}", file=self._stderr)
            write_results(result, self._out)  # with what stopping the robots found
        if self._plots and not interrupts.interrupted:
            # A signal abandons them; each file is written whole or not at all.
            with contextlib.suppress(Interrupted):
                self._written += _write_figures(self._run, self._scenario, self._out)
        self._say_written()
        return EXIT_INTERRUPTED if interrupts.interrupted else _STATUS_EXIT[result.status]

    def _say_written(self) -> None:
        if self._written:
            names = ", ".join(path.name for path in self._written)
            print(f"wrote {names} to {self._out}/", file=self._stdout)
        if self._plots and self._interrupts.interrupted:
            print("interrupted: figures not drawn", file=self._stderr)

    def leaving_at_once(self) -> contextlib.AbstractContextManager[None]:
        """Within the block a signal ends the process at once, when it is ours; else it raises.

        Inner blocks say otherwise where they must (the loop, the writes). Ending
        at once says what was written first.
        """
        streams = (self._stdout, self._stderr)
        return _leaving_at_once(self._interrupts, self._owns_process, streams, self._say_written)

    def _exit_now(self) -> NoReturn:
        """Ends the process with 130 once the output is flushed: the OS reclaims the robots."""
        _exit_process((self._stdout, self._stderr), self._say_written)


def _refused(scenario: Scenario, error: ConfigurationError, wall_time: float) -> RunResult:
    """A run refused while its robots were built: nothing ran, the reason in one line."""
    result = _not_built(scenario, wall_time)
    result.status, result.error = RunStatus.FAILED, str(error)
    return result


def _not_built(scenario: Scenario, wall_time: float) -> RunResult:
    """An interrupted run whose robots were never built: nothing ran, no target known."""
    return RunResult(
        scenario=str(scenario.path),
        app=scenario.app.name,
        item_name=getattr(scenario.app, "item_name", "item"),
        seed=scenario.run.seed,
        status=RunStatus.INTERRUPTED,
        wall_time=wall_time,
        config=scenario.data,
    )


def _leaving_at_once(
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
    return interrupts.calling(lambda: _exit_process(streams, last_words))


def _exit_process(
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


def main(
    argv: Sequence[str] | None = None,
    *,
    stdout: TextIO | None = None,
    stderr: TextIO | None = None,
    owns_process: bool = False,
) -> int:
    """Runs the command line; returns the exit code.

    SIGINT and SIGTERM (main thread only) stop it within a second, whatever it is
    doing, with exit code 130 (see :mod:`cas_async._interrupts`).

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
        with _leaving_at_once(interrupts, owns_process, (stdout, stderr)):  # nothing began
            args = parser().parse_args(argv)
            if args.command == "run":
                return _command_run(args, stdout, stderr, interrupts, owns_process)
            if args.command == "world":
                return _command_run(args, stdout, stderr, interrupts, owns_process)
            if args.command == "worker":
                return _command_worker(args, stderr)
            if args.command == "sweep":
                return _command_sweep(args, stdout, stderr, interrupts, owns_process)
            if args.command == "view":
                return views.command_view(args, stdout, stderr, interrupts)
            if args.command == "export":
                return views.command_export(args, stdout, stderr)
        raise AssertionError(f"unhandled command {args.command!r}")  # argparse requires one
    except Interrupted:
        return EXIT_INTERRUPTED
    finally:
        interrupts.restore()
        if owns_process:  # what is left is freed at exit: no collection need look at it
            gc.freeze()
