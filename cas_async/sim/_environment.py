"""The Environment: the simulated world every robot of a simulation moves in.

The thesis (§5.4) adds an Environment class, reachable only from the robotic
layer, that holds the robots' locations and simulates their sensors; it is "a
simple class accessible from a robotic layer" rather than a layer. Here it is
the same plain class, with time passed in rather than read: it knows each
robot's current :class:`~cas_async.sim._kinematics.Motion` and when it started,
so the pose of a moving robot is exact at any simulated instant, not only at
the end of a move. Range queries look only at the robots filed near the
asker in a uniform grid (:mod:`.grid`) and evaluate them at once with numpy;
a small swarm, or a query wider than the grid is useful for, evaluates every
robot instead, with the same arithmetic and so the same answer. It also keeps
each robot's odometer and the :class:`~cas_async.sim._items.ItemLedger` of the
items robots carry: hand-overs happen only between robots within reach
of each other, and a robot holding items cannot leave.

Application layers never touch it: a robotic layer reaches it through a
:class:`~cas_async.sim._middleware.SimulatedMiddleware`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from .._errors import ConfigurationError, SimulationError, UnknownRobotError
from .._pose import Pose
from .._positions import Positions
from .._types import ItemId, RobotId
from ._authority import ItemAuthority
from ._grid import CellGrid
from ._items import ItemLedger
from ._kinematics import Motion
from ._segments import SegmentTable

__all__ = ["Environment"]

# How far a motion's start may be from where the robot is, relative to the
# coordinates' magnitude: rounding, not teleporting.
_START_TOLERANCE: Final = 1e-9

# Below this many robots a range query evaluates everyone: numpy over a few dozen
# rows costs less than collecting them from the grid's cells.
_GRID_FROM: Final = 64


def _check_instant(t: float) -> None:
    if math.isnan(t):
        raise SimulationError("t must be a number, got nan")


@dataclass(slots=True)
class _Robot:
    """One robot's entry: its current motion, since when, and its row in the table."""

    index: int
    mobile: bool
    motion: Motion
    since: float
    odometer: float = 0.0  # distance translated by the motions before the current one
    # Robots this one takes items from; None: from anyone (see Environment.accept_from).
    accepting: set[RobotId] | None = None

    def travelled(self, t: float) -> float:
        """Total distance translated up to instant ``t``."""
        # A standing motion (the only kind that starts at -inf) translates nothing;
        # skipping it also avoids evaluating inf - inf.
        if self.motion.length == 0:
            return self.odometer
        return self.odometer + self.motion.travelled(t - self.since)


class Environment:
    """Poses and motions of every simulated robot, exact at any simulated instant.

    Robots keep the order in which they were added; query results that cover all
    robots follow it. Only the current motion of each robot is kept: asking about
    an instant before it started reports the pose (and odometer) it started from.

    Args:
        cell_size: the side of the range-query grid's cells (see :meth:`within`);
            ``None``: the radius of the first query with a finite radius > 0, which
            suits an application whose robots mostly ask within one radius.

    Raises:
        ValueError: ``cell_size`` is not a finite number > 0.
    """

    def __init__(self, *, cell_size: float | None = None) -> None:
        if cell_size is not None and not (math.isfinite(cell_size) and cell_size > 0):
            raise ValueError(f"cell_size must be a finite number > 0, got {cell_size!r}")
        self._robots: dict[RobotId, _Robot] = {}
        self._items = ItemLedger()
        self._table = SegmentTable()
        self._cell_size = cell_size
        # Built at the first query that uses it, then kept up to date motion by
        # motion; None again after a robot is removed (rows are renumbered).
        self._grid: CellGrid | None = None
        self._ids: npt.NDArray[np.int64] | None = None  # rebuilt after membership changes
        # positions_at() is cached for the latest instant: in a simulation many
        # robots query the same instant, and any change of motion clears it.
        self._cache: tuple[float, Positions] | None = None
        self._motion_watchers: list[Callable[[RobotId, Motion, float], None]] = []
        self._authority: ItemAuthority | None = None

    # -- across processes -------------------------------------------------------------

    def watch_motions(self, callback: Callable[[RobotId, Motion, float], None]) -> None:
        """Calls ``callback(robot_id, motion, start_time)`` after every motion started or halt.

        How a simulation spread over processes publishes each motion as its closed
        form, so every process keeps every pose (see :meth:`start_motion`).
        """
        self._motion_watchers.append(callback)

    @property
    def item_authority(self) -> ItemAuthority | None:
        """Where the hands' item operations are decided, when not in this ledger."""
        return self._authority

    @item_authority.setter
    def item_authority(self, authority: ItemAuthority | None) -> None:
        self._authority = authority

    # -- membership -------------------------------------------------------------------

    def __len__(self) -> int:
        return len(self._robots)

    def __contains__(self, robot_id: object) -> bool:
        return robot_id in self._robots

    def __repr__(self) -> str:
        return f"Environment(robots={len(self._robots)})"

    @property
    def items(self) -> ItemLedger:
        """The ledger of the items robots hold.

        Change it through :meth:`create_item`, :meth:`hand_over` and
        :meth:`retire_item`, which check the robots; read it, or subscribe to it,
        directly.
        """
        return self._items

    @property
    def robot_ids(self) -> tuple[RobotId, ...]:
        """Every robot's id, in the order they were added."""
        return tuple(self._robots)

    def add_robot(self, robot_id: RobotId, pose: Pose, *, mobile: bool = True) -> None:
        """Places a new robot, standing at ``pose``.

        Args:
            robot_id: unique among this environment's robots.
            pose: where it stands.
            mobile: ``False`` for a robot that can never move or turn.

        Raises:
            ConfigurationError: ``robot_id`` is already present.
        """
        if robot_id in self._robots:
            raise ConfigurationError(f"robot {robot_id} is already in the environment")
        motion = Motion.standing(pose)
        index = len(self._robots)
        self._robots[robot_id] = _Robot(index, mobile, motion, -math.inf)
        self._table.append(-math.inf, motion)
        if self._grid is not None:
            self._grid.place(index, pose.x, pose.y, pose.x, pose.y)
        self._ids = self._cache = None

    def remove_robot(self, robot_id: RobotId) -> None:
        """Takes a robot out of the environment (it no longer appears in queries).

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: the robot holds items, which would be lost with it.
        """
        gone = self._robot(robot_id)
        held = self._items.held_by(robot_id)
        if held:
            raise SimulationError(
                f"robot {robot_id} holds items {list(held)}: hand them over or retire "
                "them before removing it, or they would be lost"
            )
        del self._robots[robot_id]
        self._table.delete(gone.index)
        for robot in self._robots.values():
            if robot.index > gone.index:
                robot.index -= 1
        self._ids = self._cache = self._grid = None

    def is_mobile(self, robot_id: RobotId) -> bool:
        """Whether the robot can move (see :meth:`add_robot`)."""
        return self._robot(robot_id).mobile

    def _robot(self, robot_id: RobotId) -> _Robot:
        try:
            return self._robots[robot_id]
        except KeyError:
            raise UnknownRobotError(f"robot {robot_id} is not in the environment") from None

    def _robot_at(self, robot_id: RobotId, t: float) -> _Robot:
        """The robot, to be asked about instant ``t`` (checked)."""
        robot = self._robot(robot_id)
        _check_instant(t)
        return robot

    # -- motion -------------------------------------------------------------------------

    def start_motion(self, robot_id: RobotId, motion: Motion, start_time: float) -> None:
        """Makes ``motion`` the robot's current motion, beginning at ``start_time``.

        It replaces whatever the robot was doing, so ``motion.start`` must be where
        the robot is at ``start_time`` (plan it from :meth:`pose_at`).

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: the robot is immobile and the motion would change its
                pose; ``start_time`` is not finite or precedes the current motion's
                start; or ``motion`` does not start where the robot is.
        """
        robot = self._robot(robot_id)
        if not math.isfinite(start_time):
            raise SimulationError(f"start_time must be finite, got {start_time!r}")
        if start_time < robot.since:
            raise SimulationError(
                f"robot {robot_id}: a motion cannot start at {start_time!r}, before its "
                f"current one (started at {robot.since!r}): time does not go backwards"
            )
        if not robot.mobile and motion.end != motion.start:
            raise SimulationError(f"robot {robot_id} is immobile: it cannot move or turn")
        here = robot.motion.pose_at(start_time - robot.since)
        scale = _START_TOLERANCE * max(1.0, abs(here.x), abs(here.y))
        if abs(motion.start.x - here.x) > scale or abs(motion.start.y - here.y) > scale:
            raise SimulationError(
                f"robot {robot_id} is at ({here.x!r}, {here.y!r}) at {start_time!r}, but "
                f"the motion starts at ({motion.start.x!r}, {motion.start.y!r})"
            )
        robot.odometer = robot.travelled(start_time)
        robot.motion, robot.since = motion, start_time
        self._table.set(robot.index, start_time, motion)
        if self._grid is not None:
            # The robot is on this segment at every instant from now on.
            self._grid.place(
                robot.index, motion.start.x, motion.start.y, motion.end.x, motion.end.y
            )
        self._cache = None
        for watcher in self._motion_watchers:
            watcher(robot_id, motion, start_time)

    def halt(self, robot_id: RobotId, t: float) -> Pose:
        """Stops the robot where it is at ``t``; it stands there from ``t`` on.

        Halting at or after the end of a motion leaves the robot exactly at its end
        pose. Returns the pose it stopped at.

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: ``t`` is not finite or precedes the current motion's start.
        """
        pose = self.pose_at(robot_id, t)
        self.start_motion(robot_id, Motion.standing(pose), t)
        return pose

    def motion_of(self, robot_id: RobotId) -> tuple[Motion, float]:
        """The robot's current motion and the instant it started (``-inf``: always)."""
        robot = self._robot(robot_id)
        return robot.motion, robot.since

    # -- queries --------------------------------------------------------------------------

    def pose_at(self, robot_id: RobotId, t: float) -> Pose:
        """The robot's exact pose at simulated instant ``t``.

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: ``t`` is NaN.
        """
        robot = self._robot_at(robot_id, t)
        return robot.motion.pose_at(t - robot.since)

    def positions_at(self, t: float) -> Positions:
        """Every robot's position at simulated instant ``t``, in the order they were added.

        Raises:
            SimulationError: ``t`` is NaN.
        """
        _check_instant(t)
        cached = self._cache
        if cached is not None and cached[0] == t:
            return cached[1]
        ids = self._row_ids()
        xy = self._table.positions(t)
        xy.flags.writeable = False
        result = Positions(ids, xy)
        self._cache = (t, result)
        return result

    def within(self, robot_id: RobotId, radius: float, t: float) -> Positions:
        """The other robots within ``radius`` (inclusive) of ``robot_id`` at instant ``t``.

        Results are nearest first, ties broken by id. In a swarm of 64 robots or
        more, only the robots the grid files near the asker are evaluated, so a
        query costs about the number of robots around it, not the swarm's size; a
        query whose box spans more cells than there are robots evaluates everyone
        in one vectorised pass. Both give the same answer, to the last bit.

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: ``radius`` is negative or NaN (``inf`` means everyone),
                or ``t`` is NaN.
        """
        index = self._robot(robot_id).index
        if not radius >= 0:
            raise SimulationError(f"radius must be >= 0, got {radius!r}")
        _check_instant(t)
        near = self._near(index, radius, t)
        if near is None:
            everyone = self.positions_at(t)
            return _nearest_first(everyone.ids, everyone.xy, everyone.xy[index], radius, index)
        rows = np.fromiter((index, *near), dtype=np.intp, count=len(near) + 1)
        xy = self._table.positions_of(t, rows)
        return _nearest_first(self._row_ids()[rows], xy, xy[0], radius, 0)

    def _near(self, index: int, radius: float, t: float) -> set[int] | None:
        """Rows that may be within ``radius`` of row ``index`` at ``t``, itself left out.

        ``None`` when the grid would not help: a small swarm, an infinite radius, or
        a box spanning more cells than there are robots.
        """
        if len(self._robots) < _GRID_FROM or not math.isfinite(radius):
            return None
        grid = self._grid
        if grid is None:
            if self._cell_size is None:
                if radius == 0:
                    return None
                self._cell_size = radius
            grid = self._grid = self._build_grid(self._cell_size)
        x, y = self._table.positions_of(t, np.array([index], dtype=np.intp))[0].tolist()
        box = (x - radius, y - radius, x + radius, y + radius)
        if grid.cells_over(*box) > len(self._robots):
            return None
        near = grid.rows_near(*box)
        near.discard(index)
        return near

    def _build_grid(self, cell: float) -> CellGrid:
        grid = CellGrid(cell)
        for robot in self._robots.values():
            start, end = robot.motion.start, robot.motion.end
            grid.place(robot.index, start.x, start.y, end.x, end.y)
        return grid

    def _row_ids(self) -> npt.NDArray[np.int64]:
        """Every robot's id, row by row (read-only, shared with :meth:`positions_at`)."""
        if self._ids is None:
            # dicts keep insertion order, which is also the table's row order
            self._ids = np.fromiter(self._robots, dtype=np.int64, count=len(self._robots))
            self._ids.flags.writeable = False
        return self._ids

    # -- odometry -------------------------------------------------------------------------

    def distance_travelled(self, robot_id: RobotId, t: float) -> float:
        """Total distance the robot translated up to instant ``t`` (rotations add nothing).

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: ``t`` is NaN.
        """
        return self._robot_at(robot_id, t).travelled(t)

    def distances(self, t: float) -> dict[RobotId, float]:
        """Every robot's :meth:`distance_travelled` up to ``t``, in the order they were added.

        Raises:
            SimulationError: ``t`` is NaN.
        """
        _check_instant(t)
        return {robot_id: robot.travelled(t) for robot_id, robot in self._robots.items()}

    # -- items --------------------------------------------------------------------------

    def create_item(self, robot_id: RobotId, t: float) -> ItemId:
        """Creates an item in the robot's hands at instant ``t`` and returns its id.

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: ``t`` is not finite.
        """
        self._robot(robot_id)
        return self._items.create(robot_id, t)

    def hand_over(
        self, item: ItemId, giver: RobotId, receiver: RobotId, t: float, *, reach: float
    ) -> None:
        """Hands ``item`` from ``giver`` to ``receiver`` at instant ``t``, atomically.

        Args:
            item: an item ``giver`` holds.
            giver: the robot handing it over.
            receiver: another robot, within ``reach`` of ``giver`` at ``t``.
            t: the simulated instant of the hand-over.
            reach: the largest distance between the two robots' positions at which
                the hand-over may happen (inclusive).

        Raises:
            UnknownRobotError: either robot is not in the environment.
            SimulationError: ``reach`` is negative or NaN, ``t`` is not finite, the robots
                are farther apart than ``reach``, ``receiver`` does not take items from
                ``giver`` (see :meth:`accept_from`), or the ledger refuses the transfer
                (see :meth:`ItemLedger.transfer`). Nothing changes then.
        """
        self._robot(giver)
        self._robot(receiver)
        if not reach >= 0:
            raise SimulationError(f"reach must be >= 0, got {reach!r}")
        if not math.isfinite(t):  # before evaluating positions at it
            raise SimulationError(f"a hand-over's t must be a finite number, got {t!r}")
        here, there = self.pose_at(giver, t), self.pose_at(receiver, t)
        distance = math.hypot(there.x - here.x, there.y - here.y)
        if distance > reach:
            raise SimulationError(
                f"robot {giver} at ({here.x!r}, {here.y!r}) cannot hand item {item} to "
                f"robot {receiver} at ({there.x!r}, {there.y!r}) at {t!r}: they are "
                f"{distance!r} apart, beyond the reach of {reach!r}"
            )
        accepting = self._robot(receiver).accepting
        if accepting is not None and giver not in accepting:
            raise SimulationError(
                f"robot {receiver} does not take items from robot {giver} at {t!r}"
                f" (it takes them from {sorted(accepting)})"
            )
        self._items.transfer(item, giver, receiver, t)

    def accept_from(self, receiver: RobotId, giver: RobotId) -> None:
        """From now on ``receiver`` takes items from ``giver`` (and only from the givers so named).

        A robot takes items from anyone until this or :meth:`refuse_from` is first
        called for it. Holding out one's hands is a physical, atomic act: a robot
        that withdraws them (``refuse_from``) and then finds no item in them knows
        that no hand-over from that giver can happen any more, whatever messages
        were lost. That is how two robots agree on a hand-over without a reliable
        network.

        Raises:
            UnknownRobotError: either robot is not in the environment.
        """
        self._robot(giver)
        entry = self._robot(receiver)
        if entry.accepting is None:
            entry.accepting = set()
        entry.accepting.add(giver)

    def refuse_from(self, receiver: RobotId, giver: RobotId) -> None:
        """``receiver`` takes no more items from ``giver`` (see :meth:`accept_from`).

        Raises:
            UnknownRobotError: ``receiver`` is not in the environment.
        """
        entry = self._robot(receiver)
        if entry.accepting is None:
            entry.accepting = set()
        entry.accepting.discard(giver)

    def retire_item(self, item: ItemId, robot_id: RobotId, t: float) -> None:
        """Retires ``item``, held by the robot, at instant ``t``.

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: see :meth:`ItemLedger.retire`.
        """
        self._robot(robot_id)
        self._items.retire(item, robot_id, t)


def _nearest_first(
    ids: npt.NDArray[np.int64],
    xy: npt.NDArray[np.float64],
    here: npt.NDArray[np.float64],
    radius: float,
    own: int,
) -> Positions:
    """The rows of ``ids``/``xy`` within ``radius`` of ``here``, row ``own`` left out.

    Nearest first, ties broken by id. Every row's distance is computed on its own,
    so a subset of rows gets the same numbers as the whole table.
    """
    offsets = xy - here
    squared = np.einsum("ij,ij->i", offsets, offsets)
    inside = squared <= radius * radius
    inside[own] = False
    found = np.flatnonzero(inside)
    order = found[np.lexsort((ids[found], squared[found]))]
    found_ids, found_xy = ids[order], xy[order]
    found_ids.flags.writeable = found_xy.flags.writeable = False
    return Positions(found_ids, found_xy)
