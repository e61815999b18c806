"""Which of the other workers' robots a worker watches: the halo of its own, epoch by epoch.

With an interaction range ``R`` (``[network] range``), a robot acts on another only
within ``R`` of it: a range query lists it, a datagram reaches it, a hand-over
reaches it (see :class:`~cas_async.sim.Environment`). So a worker of a run across
processes need watch only the other workers' robots that can come within ``R`` of
its own, as molecular dynamics keeps only the ghost atoms within its cutoff plus a
skin: the others are hidden (in no query, in range of nobody) and their motions
kept, not applied.

Time is cut into *epochs* of ``H`` simulated seconds (:func:`epoch_steps`), a whole
number of the run's steps (see ``_windows.Steps``); windows end at every epoch's
start. At that instant each worker publishes the grid cell (of side ``D``,
:func:`cell_size`) each of its robots stands in. A robot ``b`` of another worker is
watched during epoch ``e + 1`` when its cell at ``e * H`` touches (Chebyshev
distance at most 1) a cell of one of this worker's robots: robot ``a`` moves at most
``v (2H)`` from where it was at ``e * H`` before the epoch ends, and ``b`` is seen
(``L`` late, dead reckoning) at most ``v (2H + 2L)`` from where it was, so ``D = R +
2 v (2H + 2L)``, with ``v`` the run's top speed, covers every interaction of the
epoch. A hidden robot is then farther than ``R`` from every robot of the worker all
epoch long: every query, datagram and hand-over comes out as in one process, and the
run's results are those of one process, to the bit.

Epochs ``0`` and ``1`` are watched from where the robots start, which every process
knows. The workers a worker watches robots of, or that watch its own, are its
*dependency set*, epoch by epoch.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Final, final

import numpy as np
import numpy.typing as npt

from ..._errors import ConfigurationError
from ..._types import RobotId
from ...sim._environment import Environment

__all__ = ["Halo", "cell_size", "epoch_steps", "top_speed"]

_EPOCH_SHARE: Final = 0.25
"""An epoch lets the fastest robot cross this share of the range (the skin is then half)."""
_EPOCH_MIN_WINDOWS: Final = 10
"""An epoch is at least this many latencies: a boundary costs a window."""
_EPOCH_MAX: Final = 10.0
"""Simulated seconds an epoch lasts at most (robots that hardly move)."""


def top_speed(environment: Environment) -> float:
    """The fastest any robot may translate: the run's ``v``.

    Raises:
        ConfigurationError: a mobile robot declares no top speed.
    """
    fastest = 0.0
    for robot in environment.robot_ids:
        speed = environment.top_speed(robot)
        if speed is None:
            raise ConfigurationError(
                f"robot {robot} declares no top speed: a run across processes with an "
                "interaction range needs every mobile robot's "
                "(environment.add_robot(..., top_speed=...))"
            )
        fastest = max(fastest, speed)
    return fastest


def epoch_steps(interaction_range: float, speed: float, latency: float, step: float) -> int:
    """Steps per epoch: ``H`` lets the fastest robot cross a quarter of the range.

    At least ten latencies and a step, at most 10 s, in whole steps.
    """
    if speed == 0:
        length = _EPOCH_MAX
    else:
        share = _EPOCH_SHARE * interaction_range / speed
        length = min(max(share, _EPOCH_MIN_WINDOWS * latency), _EPOCH_MAX)
    return max(1, round(length / step))


def cell_size(interaction_range: float, speed: float, epoch: float, latency: float) -> float:
    """``D = R + 2 v (2H + 2L)``: robots whose cells do not touch cannot interact (module docs)."""
    return interaction_range + 2 * speed * (2 * epoch + 2 * latency)


Cells = dict[RobotId, tuple[int, int]]


@final
class Halo:
    """What one worker watches of the others' robots, epoch by epoch (see the module docs).

    Args:
        environment: the worker's Environment, every robot in it where it starts.
        owners: every robot of the run, by the worker that runs it.
        index: this worker.
        interaction_range: the run's ``R``.
        latency: the run's ``L``.
        step: the run's step (``run.credit``): an epoch is a whole number of them.

    Raises:
        ConfigurationError: a mobile robot declares no top speed.
    """

    def __init__(
        self,
        environment: Environment,
        owners: Mapping[RobotId, int],
        index: int,
        interaction_range: float,
        latency: float,
        step: float,
    ) -> None:
        speed = top_speed(environment)
        self.steps = epoch_steps(interaction_range, speed, latency, step)
        """Steps per epoch: an epoch starts at every ``steps``-th step's end."""
        self.epoch = self.steps * step
        """``H``, simulated seconds."""
        self.cell = cell_size(interaction_range, speed, self.epoch, latency)
        """``D``: the side of the cells the workers publish."""
        self._environment = environment
        self._owners = dict(owners)
        self._index = index
        self._own = [robot for robot, owner in sorted(owners.items()) if owner == index]
        self._rows = np.fromiter(
            (environment.robot_ids.index(robot) for robot in self._own), dtype=np.intp
        )
        start = self._cells_of(environment.robot_ids, environment.positions_at(0.0).xy)
        self._next = self._sight(start)  # epoch 1, from where everyone starts
        self.visible = set(self._next)
        """The others' robots watched in the epoch under way (epoch 0: as epoch 1)."""
        self.dependencies = self._dependencies(start)
        """The workers this one watches robots of, or that watch its own, this epoch."""
        self._next_dependencies = self.dependencies

    def own_cells(self, t: float) -> list[int]:
        """Where this worker's robots stand at ``t`` (an epoch's start): robot, column, row."""
        xy = self._environment.positions_at(t).xy[self._rows]
        flat: list[int] = []
        for robot, (column, row) in zip(self._own, self._grid(xy), strict=True):
            flat += (robot, column, row)
        return flat

    def decide(self, cells: Iterable[Iterable[int]]) -> None:
        """Every worker's cells at an epoch's start: what to watch in the epoch after it.

        Call it once per epoch start, in order, before the next epoch starts.
        """
        known: Cells = {}
        for flat in cells:
            numbers = list(flat)
            for at in range(0, len(numbers), 3):
                known[numbers[at]] = (numbers[at + 1], numbers[at + 2])
        self._next = self._sight(known)
        self._next_dependencies = self._dependencies(known)

    def advance(self) -> set[RobotId]:
        """An epoch starts: the robots to watch in it (decided an epoch ago)."""
        self.visible, self.dependencies = self._next, self._next_dependencies
        return self.visible

    def _sight(self, cells: Cells) -> set[RobotId]:
        """The others' robots whose cells touch one of this worker's."""
        near = {
            (column + dx, row + dy)
            for robot in self._own
            for column, row in (cells[robot],)
            for dx in (-1, 0, 1)
            for dy in (-1, 0, 1)
        }
        owners, index = self._owners, self._index
        return {robot for robot, cell in cells.items() if owners[robot] != index and cell in near}

    def _dependencies(self, cells: Cells) -> set[int]:
        """The workers whose robots' cells touch this worker's: whom it depends on."""
        by_worker: dict[int, set[tuple[int, int]]] = {}
        for robot, cell in cells.items():
            by_worker.setdefault(self._owners[robot], set()).add(cell)
        mine = by_worker.get(self._index, set())
        near = {(c + dx, r + dy) for c, r in mine for dx in (-1, 0, 1) for dy in (-1, 0, 1)}
        return {
            worker
            for worker, theirs in by_worker.items()
            if worker != self._index and theirs & near
        }

    def _cells_of(self, ids: Iterable[RobotId], xy: npt.NDArray[np.float64]) -> Cells:
        return dict(zip(ids, self._grid(xy), strict=True))

    def _grid(self, xy: npt.NDArray[np.float64]) -> list[tuple[int, int]]:
        size = self.cell
        return [(math.floor(x / size), math.floor(y / size)) for x, y in xy.tolist()]
