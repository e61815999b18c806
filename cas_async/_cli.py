"""``python -m cas_async``: the command line.

``run SCENARIO.toml`` loads and validates the scenario (exit code 2 when it is
wrong, before anything starts), runs it with a live progress line, prints the
summary table, and writes ``results.json``, ``trace.csv`` and the PNG figures to
the output directory. Ctrl-C (or SIGTERM) stops the run cleanly and still writes
what was measured.

Exit codes: 0 the mission completed; 1 it failed or ran out of simulated time;
2 the command line or the scenario is wrong; 130 interrupted.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys
import threading
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Final, TextIO

from ._errors import ConfigurationError
from ._runner import run
from ._swarm_key import SwarmKey
from .scenario import (
    RunResult,
    RunStatus,
    Scenario,
    ScenarioError,
    check_key,
    load_scenario,
    run_scenario,
)
from .scenario._report import summary_table, write_results
from .scenario._trace import Trace

__all__ = ["main"]

EXIT_OK: Final = 0
EXIT_FAILED: Final = 1
EXIT_USAGE: Final = 2
EXIT_INTERRUPTED: Final = 130

_STATUS_EXIT: Final = {
    RunStatus.COMPLETED: EXIT_OK,
    RunStatus.FAILED: EXIT_FAILED,
    RunStatus.TIMED_OUT: EXIT_FAILED,
    RunStatus.INTERRUPTED: EXIT_INTERRUPTED,
}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m cas_async", description="cas_async: collaborative autonomous systems"
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    runner = commands.add_parser(
        "run",
        help="run a scenario file",
        description=("Run a simulation scenario (a TOML file) and write its results."),
    )
    runner.add_argument("scenario", type=Path, help="the scenario file (TOML)")
    runner.add_argument("--seed", type=int, help="random seed (overrides run.seed)")
    timing = runner.add_mutually_exclusive_group()
    timing.add_argument(
        "--time-factor",
        type=float,
        metavar="X",
        help="simulated seconds per wall second (overrides run.time_factor)",
    )
    timing.add_argument(
        "--virtual",
        action="store_true",
        help="virtual time: as fast as possible, deterministic (memory transport)",
    )
    runner.add_argument(
        "--transport", choices=("udp", "memory"), help="how robots talk (overrides run.transport)"
    )
    runner.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="where to write results.json, trace.csv and the figures "
        "(default: runs/<scenario>-seed<N>)",
    )
    runner.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    runner.add_argument(
        "--key-file",
        type=Path,
        metavar="FILE",
        help="swarm key (hex) to sign and check every datagram; default: the "
        f"{SwarmKey.ENV_VAR} environment variable, if set (never the scenario file)",
    )
    runner.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        dest="overrides",
        help="override a scenario key, e.g. strategy.name=solo",
    )
    return parser


def _overrides(args: argparse.Namespace) -> list[str]:
    """The --set overrides, then the dedicated flags (which win)."""
    overrides = list(args.overrides)
    if args.seed is not None:
        overrides.append(f"run.seed={args.seed}")
    if args.time_factor is not None:
        overrides += [f"run.time_factor={args.time_factor!r}", "run.virtual=false"]
    if args.virtual:
        overrides.append("run.virtual=true")
        if args.transport is None:
            overrides.append('run.transport="memory"')
    if args.transport is not None:
        overrides.append(f'run.transport="{args.transport}"')
    return overrides


async def _run_until_signalled(
    scenario: Scenario, stream: TextIO, key: SwarmKey | None
) -> tuple[RunResult, Trace]:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    handled = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(signum, stop.set)
            handled.append(signum)
        except (NotImplementedError, RuntimeError):  # not the main thread, or no support
            pass
    try:
        return await run_scenario(scenario, progress_to=stream, stop=stop, key=key)
    finally:
        for signum in handled:
            loop.remove_signal_handler(signum)


def _write_outputs(
    result: RunResult, trace: Trace, scenario: Scenario, out: Path, plots: bool
) -> list[Path]:
    written = [write_results(result, out)]
    trace_path = out / "trace.csv"
    trace.write_csv(trace_path)
    written.append(trace_path)
    if plots:
        from .scenario._plots import write_plots  # matplotlib is imported only here

        title = f"{result.app}, {scenario.path.name}, seed {result.seed}"
        written += write_plots(
            trace,
            result.groups,
            (scenario.world.width, scenario.world.height),
            out,
            title=title,
            exchanges_traced=scenario.run.trace_exchanges,
        )
    return written


def _command_run(args: argparse.Namespace, stdout: TextIO, stderr: TextIO) -> int:
    try:
        scenario = load_scenario(args.scenario, _overrides(args))
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
    try:  # before the run: a long run must not end in "cannot write"
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"error: --out {out}: {exc.strerror or exc}", file=stderr)
        return EXIT_USAGE
    result, trace = run(_run_until_signalled(scenario, stderr, key), virtual=scenario.run.virtual)
    with _signals_deferred() as signalled:  # what was measured is written whatever comes
        print(summary_table(result), file=stdout)
        if result.traceback:
            print(result.traceback, file=stderr)
        written = _write_outputs(result, trace, scenario, out, not args.no_plots)
        print(f"wrote {', '.join(path.name for path in written)} to {out}/", file=stdout)
    return EXIT_INTERRUPTED if signalled else _STATUS_EXIT[result.status]


@contextlib.contextmanager
def _signals_deferred() -> Iterator[list[int]]:
    """SIGINT and SIGTERM are noted, not acted on, inside the block (main thread only)."""
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return
    previous = {
        signum: signal.signal(signum, lambda signum, _frame: received.append(signum))
        for signum in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield received
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def main(
    argv: Sequence[str] | None = None, *, stdout: TextIO | None = None, stderr: TextIO | None = None
) -> int:
    """Runs the command line; returns the exit code."""
    stdout = stdout or sys.stdout
    stderr = stderr or sys.stderr
    args = _parser().parse_args(argv)
    if args.command == "run":
        return _command_run(args, stdout, stderr)
    raise AssertionError(f"unhandled command {args.command!r}")  # argparse requires one
