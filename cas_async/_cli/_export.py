"""``export RUN_DIR --format mcap [--out FILE]``: a run directory as a ROS 2 bag (MCAP)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TextIO

from ..live import RecordingError, export_mcap
from ._exits import EXIT_OK, EXIT_USAGE

__all__ = ["command_export"]


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
