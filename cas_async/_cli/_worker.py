"""``worker --connect ENDPOINT``: a worker process of a run across processes, started by hand."""

from __future__ import annotations

import argparse
from typing import TextIO

from .._errors import ConfigurationError
from .._wire._swarm_key import SwarmKey
from ..scenario._processes._lost import WorkerLost
from ..scenario._processes._worker import run_worker
from ._exits import EXIT_FAILED, EXIT_USAGE

__all__ = ["command_worker"]


def command_worker(args: argparse.Namespace, stderr: TextIO) -> int:
    try:
        key = SwarmKey.from_file(args.key_file) if args.key_file else SwarmKey.from_env()
        return run_worker(args.connect, key, listen=args.listen, quiet=args.quiet, wait=args.wait)
    except ConfigurationError as exc:
        print(f"error: {exc}", file=stderr)
        return EXIT_USAGE
    except WorkerLost as exc:  # no world answered, or it went away
        print(f"error: {exc}", file=stderr)
        return EXIT_FAILED
