"""``view RUN_DIR [--port P]``: a finished run replayed in the browser until a signal (exit 0)."""

from __future__ import annotations

import argparse
import asyncio
from typing import TextIO

from .._errors import ConfigurationError
from ..live import RecordingError, ReplayView
from ._exits import EXIT_OK, EXIT_USAGE
from ._interrupts import Interrupts

__all__ = ["command_view"]


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
