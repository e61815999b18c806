"""The command line's views: ``run --live``, ``view RUN_DIR`` and ``export RUN_DIR``.

``run ... --live [HOST:]PORT`` serves the run's live view (see
:class:`cas_async.live.LiveView`): the port is bound before the robots start,
and ``live view: http://HOST:PORT/`` printed with the port it got (0 picks a
free one). ``--live-fps N`` caps the frames per wall second, ``--live-pace X``
holds a virtual run to X simulated seconds per wall second, ``--live-wait``
starts the robots only once a viewer is connected (a signal still stops it).

``view RUN_DIR [--port P]`` serves the same page over a finished run's directory
until a signal stops it (exit 0). ``export RUN_DIR --format mcap [--out FILE]``
writes it as a ROS 2 bag (the ``mcap`` extra).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import math
import socket
import warnings
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, TextIO

from ._errors import ConfigurationError
from ._interrupts import Interrupts
from .live import LiveView, RecordingError, ReplayView, export_mcap
from .live._server import is_loopback
from .scenario import Scenario, ScenarioRun
from .transport import InsecureBindWarning

__all__ = [
    "LiveOptions",
    "add_live_arguments",
    "add_view_commands",
    "command_export",
    "command_view",
    "open_live",
    "serve_live",
]

EXIT_OK: Final = 0
EXIT_USAGE: Final = 2


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


def command_view(
    args: argparse.Namespace, stdout: TextIO, stderr: TextIO, interrupts: Interrupts
) -> int:
    """``view RUN_DIR``: serves the replay until a signal (exit 0)."""
    try:
        replay = ReplayView(args.run_dir, host=args.host, port=args.port)
    except RecordingError as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE

    async def serve() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()

        def stop_serving() -> None:  # from the signal handler: only schedules
            loop.call_soon_threadsafe(stop.set)

        with interrupts.calling(stop_serving):
            async with replay:
                samples = len(replay.recording)
                print(
                    f"replay: {replay.url} ({samples} samples; Ctrl-C stops)",
                    file=stdout,
                    flush=True,
                )
                await stop.wait()

    try:
        asyncio.run(serve())
    except ConfigurationError as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE
    print("replay stopped", file=stderr)
    return EXIT_OK


def command_export(args: argparse.Namespace, stdout: TextIO, stderr: TextIO) -> int:
    """``export RUN_DIR --format mcap``: writes the bag; exit 2 naming what is wrong."""
    out: Path = args.out or args.run_dir / "run.mcap"
    try:
        samples = export_mcap(args.run_dir, out)
    except (RecordingError, ImportError, OSError) as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE
    print(f"wrote {out} ({samples} samples)", file=stdout)
    return EXIT_OK
