"""The command line's arguments: ``python -m cas_async COMMAND ...`` (see :mod:`._cli`)."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import Any

from .._wire._swarm_key import SwarmKey
from ..scenario import FailOnDrops, ScenarioError, parse_override
from ..scenario._processes._joining import CONNECT_WAIT

_LONGEST_WAIT = 86_400.0

__all__ = ["overrides_of", "parser"]


def parser() -> argparse.ArgumentParser:
    """The command line's parser: every command and option, with its help."""
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
        "--transport",
        choices=("udp", "memory", "zenoh"),
        help="how robots talk (overrides run.transport)",
    )
    runner.add_argument(
        "--processes",
        type=_at_least_one,
        metavar="N",
        help="run the robots in N worker processes on Zenoh, this process being the world "
        "(needs the zenoh extra); virtual time too",
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
        "--fail-on-drops",
        nargs="?",
        const=FailOnDrops(),
        type=_drop_reasons,
        metavar="REASON,...",
        help="the run fails (exit 1) if its robots dropped messages for these reasons "
        "(decode: every decode.* reason), or for any reason when none is given",
    )
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
    add_live_arguments(runner)
    world = commands.add_parser(
        "world",
        help="be the world of a run whose workers join from other hosts",
        description="Load a scenario, listen for N workers (python -m cas_async worker), run "
        "it with them, and write its results as `run` does. Every message is signed with the "
        "swarm key.",
    )
    world.add_argument("scenario", type=Path, help="the scenario file (TOML)")
    world.add_argument("--listen", required=True, metavar="ENDPOINT",
                       help="where workers connect, e.g. tcp/192.0.2.1:7447")  # fmt: skip
    world.add_argument("--workers", type=_at_least_one, required=True, metavar="N",
                       help="how many workers to wait for")  # fmt: skip
    world.add_argument("--key-file", type=Path, required=True, metavar="FILE",
                       help="the swarm key (hex); every worker needs the same")  # fmt: skip
    world.add_argument("--seed", type=int, help="random seed (overrides run.seed)")
    world.add_argument("--virtual", action="store_true", help="virtual time, shared by barrier")
    world.add_argument("--out", type=Path, metavar="DIR", help="where to write")
    world.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    world.add_argument("--fail-on-drops", nargs="?", const=FailOnDrops(), type=_drop_reasons,
                       metavar="REASON,...", help="fail the run on these drops")  # fmt: skip
    world.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                       dest="overrides", help="override a scenario key")  # fmt: skip
    add_live_arguments(world)
    worker = commands.add_parser(
        "worker",
        help="run a share of the robots of a world's run",
        description="Connect to a world (python -m cas_async world or run --processes), "
        "receive the scenario from it, and run this worker's share of the robots.",
    )
    worker.add_argument("--connect", required=True, metavar="ENDPOINT",
                        help="the world's Zenoh endpoint, e.g. tcp/192.0.2.1:7447")  # fmt: skip
    worker.add_argument("--key-file", type=Path, metavar="FILE",
                        help=f"the swarm key (hex); default: {SwarmKey.ENV_VAR}")  # fmt: skip
    worker.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                        help="also listen here, so other workers link to this one directly "
                        "(peer mode); default: everything through the world's router")  # fmt: skip
    worker.add_argument("--wait", type=_wait, default=CONNECT_WAIT, metavar="SECONDS",
                        help="wait this long for the world to listen at --connect, trying "
                        f"again (default {CONNECT_WAIT:g}; 0: fail at once)")  # fmt: skip
    worker.add_argument("--quiet", action="store_true",
                        help="do not say which robots this worker runs (on stderr)")  # fmt: skip
    sweeper = commands.add_parser(
        "sweep",
        help="run a scenario over a grid of values and seeds",
        description="Run a scenario for seeds 1..N at every point of a grid (the cartesian "
        "product of the --vary values) in parallel worker processes or on a Dask cluster, on "
        "virtual time; write sweep.json, runs.csv (as runs finish), table.md, summary.json and "
        "box plots, and print the table.",
    )
    sweeper.add_argument("scenario", type=Path, help="the scenario file (TOML)")
    add = sweeper.add_argument
    add("--seeds", type=_at_least_one, required=True, metavar="N", help="seeds 1..N per point")
    add("--vary", action="append", default=[], metavar="KEY=A,B,...",
        help="vary a key over these values (TOML, or bare text), e.g. strategy.name=time,solo; "
        "several --vary make a grid")  # fmt: skip
    add("--set", action="append", default=[], metavar="KEY=VALUE", dest="overrides",
        help='override a key in every run, after run.virtual=true and run.transport="memory" '
        "(run.virtual=false: scaled real time, slow)")  # fmt: skip
    add("--out", type=Path, metavar="DIR", help="where to write (default: runs/sweep-<scenario>)")
    add("--resume", action="store_true",
        help="keep the runs already finished in --out (the same scenario and grid), run the "
        "others")  # fmt: skip
    where = sweeper.add_mutually_exclusive_group().add_argument  # here, or on a cluster
    where("--jobs", type=_at_least_one, metavar="J",
          help=f"worker processes (default: the CPUs, {os.cpu_count()} here)")  # fmt: skip
    where("--cluster", metavar="ADDRESS",
          help="run on the workers of the Dask scheduler at ADDRESS, e.g. tcp://192.0.2.1:8786 "
          "(needs the dask extra)")  # fmt: skip
    add("--no-plots", action="store_true", help="skip the box plots")
    add_view_commands(commands)
    return parser


def _at_least_one(text: str) -> int:
    try:
        number = int(text)
    except ValueError:
        number = 0
    if number < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least 1, got {text!r}")
    return number


def _wait(text: str) -> float:
    try:
        seconds = float(text)
    except ValueError:
        seconds = math.nan
    if not 0 <= seconds <= _LONGEST_WAIT:
        raise argparse.ArgumentTypeError(
            f"expected seconds from 0 to {_LONGEST_WAIT:g} (a day), got {text!r}"
        )
    return seconds


def _drop_reasons(text: str) -> FailOnDrops:
    try:
        return FailOnDrops.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def overrides_of(args: argparse.Namespace) -> list[str]:
    """The ``--set`` overrides, then what the dedicated flags set.

    A flag sets its key over the file's value. A ``--set`` of a key that a flag
    also sets must say the same (``--seed 3`` with ``--set run.seed=3``), or both
    are refused, so that the user's value is never dropped unchecked (every ``--set``
    value left is validated with the file, as the file's own). ``--virtual`` makes
    the memory transport the default, which a transport named by ``--transport``
    or ``--set run.transport`` replaces (and the file's checks refuse UDP).

    Raises:
        ScenarioError: a malformed ``--set``, or one that contradicts a flag (naming
            the key, and both).
    """
    overrides = list(args.overrides)
    named = {key: (text, value) for text in overrides for key, value in [parse_override(text)]}
    flags: list[tuple[str, str, Any]] = []  # (the flag as typed, key, value)
    if args.seed is not None:
        flags.append((f"--seed {args.seed}", "run.seed", args.seed))
    time_factor = getattr(args, "time_factor", None)
    if time_factor is not None:
        flag = f"--time-factor {time_factor:g}"
        flags += [(flag, "run.time_factor", time_factor), (flag, "run.virtual", False)]
    if args.virtual:
        flags.append(("--virtual", "run.virtual", True))
    transport = getattr(args, "transport", None)
    if transport is not None:
        flags.append((f"--transport {transport}", "run.transport", transport))
    elif args.virtual and "run.transport" not in named:
        flags.append(("--virtual", "run.transport", "memory"))
    problems = [
        (key, f"--set {named[key][0]!r} contradicts {flag}: give one of them")
        for flag, key, value in flags
        if key in named and not _agree(named[key][1], value)
    ]
    if problems:
        raise ScenarioError(problems)
    return [*overrides, *(f"{key}={_toml(value)}" for _, key, value in flags)]


def _agree(given: Any, flag: Any) -> bool:
    """Whether a ``--set`` value is the flag's (an integer for a float flag is)."""
    if type(given) is type(flag):
        return bool(given == flag)
    return type(given) is int and type(flag) is float and given == flag


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    return repr(value)


def _address(text: str) -> tuple[str, int]:
    """``PORT``, ``HOST:PORT`` or ``[IPv6]:PORT``; loopback when no host is given."""
    host, colon, port = text.rpartition(":")
    if not colon:
        host, port = "127.0.0.1", text
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise argparse.ArgumentTypeError(
            f"expected [HOST:]PORT with a port from 0 to 65535 (0: any free one), got {text!r}"
        )
    return host.strip("[]") or "127.0.0.1", int(port)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def add_live_arguments(parser: argparse.ArgumentParser) -> None:
    """``--live``, ``--live-fps``, ``--live-pace``, ``--live-wait`` on ``run`` (and ``world``)."""
    add = parser.add_argument
    add("--live", type=_address, metavar="[HOST:]PORT",
        help="serve a live view of the run in the browser (0: any free port; loopback unless "
        "a host is given)")  # fmt: skip
    add("--live-fps", type=_positive, default=10.0, metavar="N",
        help="live view: frames per wall second, at most (default 10)")  # fmt: skip
    add("--live-pace", type=_positive, metavar="X",
        help="live view: hold a virtual run to X simulated seconds per wall second")  # fmt: skip
    add("--live-wait", action="store_true",
        help="live view: start the robots once a viewer is connected")  # fmt: skip


def add_view_commands(commands: Any) -> None:
    """The ``view`` and ``export`` subcommands."""
    view = commands.add_parser(
        "view",
        help="replay a finished run in the browser",
        description="Serve the live view's page over a run directory (trace.csv, results.json, "
        "scene.json), with play, pause, speed and a time scrubber, until interrupted.",
    )
    view.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run's output directory")
    view.add_argument("--port", type=int, default=0, metavar="P", help="default: any free port")
    view.add_argument("--host", default="127.0.0.1", help="default: 127.0.0.1 (loopback)")
    export = commands.add_parser(
        "export",
        help="write a finished run as a ROS 2 bag (MCAP)",
        description="Write a run directory as an MCAP file of ROS 2 messages (PoseArray per "
        "sample, Float64 per measure, markers for the scene): Foxglove, Lichtblick, "
        "ros2 bag and Rerun open it. Needs the mcap extra.",
    )
    export.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run's output directory")
    export.add_argument("--format", required=True, choices=("mcap",), help="the file's format")
    export.add_argument("--out", type=Path, metavar="FILE", help="default: RUN_DIR/run.mcap")
