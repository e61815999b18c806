"""Where a robot is in its one-way lifecycle."""

from __future__ import annotations

import enum

__all__ = ["RobotState"]


class RobotState(enum.StrEnum):
    """Where a robot is in its (one-way) lifecycle.

    ``CREATED`` --:meth:`~cas_async.Robot.open`--> ``OPEN``
    --:meth:`~cas_async.Robot.start`--> ``RUNNING``
    --:meth:`~cas_async.Robot.close`--> ``STOPPED``; ``async with robot:`` does
    all of it. A robot never runs twice.
    """

    CREATED = "created"
    OPEN = "open"
    RUNNING = "running"
    STOPPED = "stopped"
