"""Which worker process runs which robot: neighbours together, so that most traffic stays home.

A run across processes is exact whatever the partition (see :mod:`._windows`): the
partition only decides how much of the robots' traffic crosses processes, hence
how much each window has to carry. ``"region"`` (the default) cuts the world into
strips along its longer side, each holding as many robots as the others (give or
take one), so robots that start near each other, and mostly talk to each other,
share a process. ``"round_robin"`` deals them out in turn: robots ``k``, ``k + n``,
``k + 2n``... to worker ``k``. An application may choose its own with a
``partition(environment, robots, workers)`` method (see :class:`Partitioner`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal, Protocol

from ..._types import RobotId
from ...sim._environment import Environment

__all__ = ["PartitionKind", "Partitioner", "lost_robots", "partition"]

PartitionKind = Literal["region", "round_robin"]


class Partitioner(Protocol):
    """An application that chooses its own partition (an optional app member)."""

    def partition(
        self, environment: Environment, robots: Sequence[RobotId], workers: int
    ) -> Sequence[Sequence[RobotId]]:
        """``workers`` groups of ``robots`` (every robot in exactly one, none empty)."""


def partition(
    environment: Environment,
    robots: Sequence[RobotId],
    workers: int,
    kind: PartitionKind,
    app: object = None,
) -> list[list[RobotId]]:
    """The robots each of ``workers`` processes runs, by ``kind`` (or the app's own).

    Raises:
        ValueError: more workers than robots, or an app's partition that is not
            ``workers`` groups covering every robot once.
    """
    if not 1 <= workers <= len(robots):
        raise ValueError(f"{len(robots)} robots cannot be shared by {workers} workers")
    chooser = getattr(app, "partition", None)
    if callable(chooser):
        groups = [list(group) for group in chooser(environment, robots, workers)]
        _check(groups, robots, workers)
        return groups
    if kind == "round_robin":
        return [list(robots[k::workers]) for k in range(workers)]
    return _strips(environment, robots, workers)


def _strips(
    environment: Environment, robots: Sequence[RobotId], workers: int
) -> list[list[RobotId]]:
    positions = {robot: environment.pose_at(robot, 0.0) for robot in robots}
    xs = [pose.x for pose in positions.values()]
    ys = [pose.y for pose in positions.values()]
    along_x = max(xs) - min(xs) >= max(ys) - min(ys)
    order = sorted(
        robots,
        key=lambda r: (
            (positions[r].x, positions[r].y, r) if along_x else (positions[r].y, positions[r].x, r)
        ),
    )
    size, extra = divmod(len(order), workers)
    groups, start = [], 0
    for k in range(workers):
        end = start + size + (1 if k < extra else 0)
        groups.append(order[start:end])
        start = end
    return groups


def _check(groups: list[list[RobotId]], robots: Sequence[RobotId], workers: int) -> None:
    flat = [robot for group in groups for robot in group]
    if len(groups) != workers or any(not group for group in groups):
        raise ValueError(f"the app's partition must be {workers} groups, none empty")
    if sorted(flat) != sorted(robots):
        raise ValueError("the app's partition must hold every robot exactly once")


def lost_robots(shares: Sequence[Sequence[RobotId]], workers: Sequence[int]) -> str:
    """``; its N robots are lost: 1, 3, ...``: what a loss of these workers costs, for its error."""
    ids = [robot for w in workers if w < len(shares) for robot in shares[w]]
    if not ids:
        return ""
    shown = ", ".join(str(i) for i in ids[:20])
    more = f", ... ({len(ids) - 20} more)" if len(ids) > 20 else ""
    return f"; {'their' if len(workers) > 1 else 'its'} {len(ids)} robots are lost: {shown}{more}"
