"""``run SCENARIO.toml`` (and ``world``): one run, its results, its figures, its live view.

``run`` loads and validates the scenario (exit code 2 when it is wrong, before
anything starts), runs it with a live progress line, prints the summary table, and
writes ``results.json``, ``trace.csv`` and the PNG figures to the output directory.
``--processes N`` runs the robots in N worker processes, this process being the
world (``world`` is the same with workers started by hand).

SIGINT and SIGTERM stop it within a second at any moment. While the scenario
loads, nothing is written; while the robots are built, ``results.json`` says the
run was interrupted before anything ran. Once the robots run, what was measured is
written first (``results.json``; ``trace.csv`` is written as the run goes, so
little is left); as ``python -m cas_async`` the process then exits at once, leaving
the robots and their sockets to the OS, without the figures. A file is always
written whole or not at all.

Exit codes (see :mod:`._exits`): 0 the mission completed; 1 it failed or ran out of
simulated time; 2 anything refused before the robots run (the app's build
refusing, ``--processes`` without the zenoh extra or with an objective that cannot
run across processes, a start refused by a transport or a clock; ``results.json``
says so too); 130 interrupted. A run across processes whose workers do not come,
or go during the start, fails on one line too, with exit code 1 and ``results.json``.

``--live [HOST:]PORT`` serves the run's live view (see
:class:`cas_async.live.LiveView`): the port is bound before the robots start, and
``live view: http://HOST:PORT/`` printed with the port it got (0 picks a free
one). ``--live-fps N`` caps the frames per wall second, ``--live-pace X`` holds a
virtual run to X simulated seconds per wall second, ``--live-wait`` starts the
robots only once a viewer is connected (a signal still stops it).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import gc
import socket
import time
import warnings
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn, TextIO, final

from .._errors import ConfigurationError
from .._time._loop_factory import run
from .._wire._swarm_key import SwarmKey
from ..live import LiveView, write_scene
from ..live._server import is_loopback
from ..scenario import (
    FailOnDrops,
    RunResult,
    RunStatus,
    Scenario,
    ScenarioError,
    ScenarioRun,
    check_key,
    load_scenario,
)
from ..scenario._processes._lost import WorkerLost, WorkerRefused
from ..scenario._processes._world import World
from ..scenario.output import summary_table, write_results
from ..transport import InsecureBindWarning
from ..transport.zenoh import import_zenoh
from ._exits import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    STATUS_EXIT,
    exit_process,
    leaving_at_once,
    made,
)
from ._interrupts import Interrupted, Interrupts
from ._parser import overrides_of

__all__ = ["LiveOptions", "command_run"]


def command_run(
    args: argparse.Namespace,
    stdout: TextIO,
    stderr: TextIO,
    interrupts: Interrupts,
    owns_process: bool,
) -> int:
    try:
        scenario = load_scenario(args.scenario, overrides_of(args))
    except ScenarioError as exc:
        print(f"error: {exc if exc.file else exc.with_file(str(args.scenario))}", file=stderr)
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
        with leaving_at_once(interrupts, owns_process, (stdout, stderr), abandon_build):
            if not made(out, stderr):
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
        live = open_live(args, scenario, stdout)  # bound now: the robots start on the loop
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
        self.live: LiveOptions | None = None
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
            await stack.enter_async_context(serve_live(self.live, self._run, stop, self._stderr))
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
        return EXIT_INTERRUPTED if interrupts.interrupted else STATUS_EXIT[result.status]

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
        return leaving_at_once(self._interrupts, self._owns_process, streams, self._say_written)

    def _exit_now(self) -> NoReturn:
        """Ends the process with 130 once the output is flushed: the OS reclaims the robots."""
        exit_process((self._stdout, self._stderr), self._say_written)


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


def _write_figures(scenario_run: ScenarioRun, scenario: Scenario, out: Path) -> list[Path]:
    from ..scenario.output._plots import write_plots  # matplotlib is imported only here

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


@dataclass(slots=True)
class LiveOptions:
    """``run --live``: the socket bound before anything runs, and how to serve on it."""

    sock: socket.socket
    fps: float
    pace: float | None
    wait: bool


def open_live(args: argparse.Namespace, scenario: Scenario, stdout: TextIO) -> LiveOptions | None:
    """Binds ``--live``'s address and prints the page's address; ``None`` without ``--live``.

    Raises:
        ConfigurationError: a ``--live-*`` option without ``--live``, ``--live-pace``
            on scaled time, or the address cannot be bound.
    """
    if getattr(args, "live", None) is None:
        if getattr(args, "live_pace", None) is not None or getattr(args, "live_wait", False):
            raise ConfigurationError("--live-pace and --live-wait need --live [HOST:]PORT")
        return None
    if args.live_pace is not None and not scenario.run.virtual:
        raise ConfigurationError(
            "--live-pace holds a run on virtual time; this one runs on scaled time, whose pace "
            "is run.time_factor: leave --live-pace out, or add --virtual"
        )
    host, port = args.live
    if not is_loopback(host):
        warnings.warn(
            f"--live {host}:{port}: the live view is served beyond this machine to anyone who "
            "can reach it, without authentication; prefer 127.0.0.1 and ssh -L to watch remotely",
            InsecureBindWarning,
            stacklevel=2,
        )
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        sock = socket.create_server((host, port), family=family)
    except OSError as exc:
        raise ConfigurationError(f"--live {host}:{port}: {exc.strerror or exc}") from None
    shown = f"[{host}]" if ":" in host else host
    if host in ("0.0.0.0", "::"):
        shown = "127.0.0.1"
    print(f"live view: http://{shown}:{sock.getsockname()[1]}/", file=stdout, flush=True)
    return LiveOptions(sock, args.live_fps, args.live_pace, args.live_wait)


@contextlib.asynccontextmanager
async def serve_live(
    options: LiveOptions | None, run: ScenarioRun, stop: asyncio.Event, stderr: TextIO
) -> AsyncIterator[None]:
    """Serves ``run``'s live view for the block (nothing without ``--live``)."""
    if options is None:
        yield
        return
    view = LiveView(run, sock=options.sock, fps=options.fps, pace=options.pace, stop=stop)
    async with view:
        if options.wait:
            print("waiting for a viewer to connect...", file=stderr, flush=True)
            await view.wait_for_viewer()
        yield
