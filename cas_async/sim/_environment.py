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
:class:`~cas_async.sim._simulated.SimulatedMiddleware`.

With a ``latency`` (the simulation's network model: the least simulated time any
effect needs to go from one robot to another), a robot's motion is *seen* by the
others only ``latency`` after it started: range queries (:meth:`within`) place the
asker where it really is and every other robot where its last motion seen says it
is, the motion it was on ``latency`` ago carried on to now (dead reckoning, as a
robot does with a neighbour's last broadcast). The motions seen change at their
instants in a fixed order (see :mod:`cas_async._time._deliveries`), so what a robot
senses does not depend on which robots share its process. Item hand-overs take
the latency too (see :meth:`hand_over`).

With an ``interaction_range`` (``R``: the furthest a robot senses and its messages
and hands reach), a range query wider than ``R``, or a hand-over reaching farther,
is an error naming the range, and :meth:`in_range` says whether one robot reaches
another (what a simulated radio asks of every datagram). A robot may declare its
``top_speed``: no motion of it may go faster. Together they bound where a robot
can act on another, which is what lets a run across processes hold and watch only
the robots near its own.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import Final

import numpy as np
import numpy.typing as npt

from .._body._pose import Pose
from .._body._positions import Positions
from .._errors import ConfigurationError, SimulationError, UnknownRobotError
from .._time._clock import Clock
from .._time._deliveries import MOTION
from .._types import RobotId
from ._entries import Courier, RobotEntry, check_instant
from ._grid import CellGrid, nearest_first
from ._handovers import Handovers
from ._items import ItemLedger
from ._kinematics import Motion
from ._segments import SegmentTable

__all__ = ["Environment"]

# How far a motion's start may be from where the robot is, relative to the
# coordinates' magnitude: rounding, not teleporting.
_START_TOLERANCE: Final = 1e-9

# How much faster than its top speed a motion may seem: rounding, not speeding.
_SPEED_TOLERANCE: Final = 1 + 1e-9

# How near the range's square a distance's square may be for in_range to redo it
# with within's own arithmetic (numpy may fuse its multiply and add: an ulp apart).
_CLOSE_CALL: Final = 1e-9

# Below this many robots a range query evaluates everyone: numpy over a few dozen
# rows costs less than collecting them from the grid's cells.
_GRID_FROM: Final = 64


class Environment(Handovers):
    """Poses and motions of every simulated robot, exact at any simulated instant.

    Robots keep the order in which they were added; query results that cover all
    robots follow it. Only the current motion of each robot is kept: asking about
    an instant before it started reports the pose (and odometer) it started from.

    Args:
        cell_size: the side of the range-query grid's cells (see :meth:`within`);
            ``None``: the radius of the first query with a finite radius > 0, which
            suits an application whose robots mostly ask within one radius.
        latency: simulated seconds before a robot's motion is seen by the others,
            and an item handed over arrives (see the module docs); 0: at once.
        clock: the robots' clock (needed with a latency: it says when an instant
            comes on the event loop).
        interaction_range: the furthest a robot senses and its messages and hands
            reach (``None``: no limit; see the module docs).

    Raises:
        ValueError: ``cell_size`` is not a finite number > 0, ``latency`` is not a
            finite number >= 0, a latency comes without a clock, or
            ``interaction_range`` is not a finite number > 0.
    """

    def __init__(
        self,
        *,
        cell_size: float | None = None,
        latency: float = 0.0,
        clock: Clock | None = None,
        interaction_range: float | None = None,
    ) -> None:
        if cell_size is not None and not (math.isfinite(cell_size) and cell_size > 0):
            raise ValueError(f"cell_size must be a finite number > 0, got {cell_size!r}")
        if not (math.isfinite(latency) and latency >= 0):
            raise ValueError(f"latency must be a finite number >= 0, got {latency!r}")
        if latency > 0 and clock is None:
            raise ValueError("an Environment with a latency needs the robots' clock")
        if interaction_range is not None and not (
            math.isfinite(interaction_range) and interaction_range > 0
        ):
            raise ValueError(
                f"interaction_range must be a finite number > 0, got {interaction_range!r}"
            )
        self.interaction_range = interaction_range
        """The furthest a robot senses and reaches (``None``: no limit)."""
        self.latency = latency
        """Simulated seconds before others see a motion, and a handed item arrives."""
        self._clock = clock
        self._robots: dict[RobotId, RobotEntry] = {}
        self._items = ItemLedger(ids_by_creator=latency > 0)
        self._sending: dict[tuple[RobotId, int], asyncio.Future[None]] = {}  # hand-overs
        self._courier: Courier | None = None
        self._table = SegmentTable()
        # With a latency: the motions the others see (own rows are never read from it).
        self._seen = SegmentTable() if latency > 0 else None
        self._cell_size = cell_size
        # Built at the first query that uses it, then kept up to date motion by
        # motion; None again after a robot is removed (rows are renumbered).
        self._grid: CellGrid | None = None
        self._ids: npt.NDArray[np.int64] | None = None  # rebuilt after membership changes
        # positions_at() is cached for the latest instant: in a simulation many
        # robots query the same instant, and any change of motion clears it.
        self._cache: tuple[float, Positions] | None = None
        self._motion_watchers: list[Callable[[RobotId, Motion, float], None]] = []

    # -- across processes -------------------------------------------------------------

    def watch_motions(self, callback: Callable[[RobotId, Motion, float], None]) -> None:
        """Calls ``callback(robot_id, motion, start_time)`` after every motion started or halt.

        How a simulation spread over processes publishes each motion as its closed
        form, so every process keeps every pose (see :meth:`start_motion`).
        """
        self._motion_watchers.append(callback)

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

    def add_robot(
        self, robot_id: RobotId, pose: Pose, *, mobile: bool = True, top_speed: float | None = None
    ) -> None:
        """Places a new robot, standing at ``pose``.

        Args:
            robot_id: unique among this environment's robots.
            pose: where it stands.
            mobile: ``False`` for a robot that can never move or turn.
            top_speed: the fastest the robot can translate (distance units per
                second); no motion of it may be faster. ``None``: unbounded; an
                immobile robot's is 0.

        Raises:
            ConfigurationError: ``robot_id`` is already present, or ``top_speed`` is
                not a finite number >= 0.
        """
        if robot_id in self._robots:
            raise ConfigurationError(f"robot {robot_id} is already in the environment")
        if top_speed is not None and not (math.isfinite(top_speed) and top_speed >= 0):
            raise ConfigurationError(
                f"robot {robot_id}: top_speed must be a finite number >= 0, got {top_speed!r}"
            )
        motion = Motion.standing(pose)
        index = len(self._robots)
        self._robots[robot_id] = RobotEntry(
            index, mobile, motion, -math.inf, seen=motion,
            top_speed=top_speed if mobile else 0.0,
        )  # fmt: skip
        self._table.append(-math.inf, motion)
        if self._seen is not None:
            self._seen.append(-math.inf, motion)
        if self._grid is not None:
            self._grid.place(index, pose.x, pose.y, pose.x, pose.y)
        self._ids = self._cache = None

    def remove_robot(self, robot_id: RobotId) -> None:
        """Takes a robot out of the environment (it no longer appears in queries).

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: the robot holds items, or items are on their way to or
                from it (with a latency): they would be lost with it.
        """
        gone = self._robot(robot_id)
        held = self._items.held_by(robot_id)
        if held:
            raise SimulationError(
                f"robot {robot_id} holds items {list(held)}: hand them over or retire "
                "them before removing it, or they would be lost"
            )
        travelling = self._items.travelling_with(robot_id)
        if travelling:
            raise SimulationError(
                f"items {list(travelling)} are on their way to or from robot {robot_id}: "
                "let their hand-overs end before removing it, or they would be lost"
            )
        del self._robots[robot_id]
        self._table.delete(gone.index)
        if self._seen is not None:
            self._seen.delete(gone.index)
        for robot in self._robots.values():
            if robot.index > gone.index:
                robot.index -= 1
        self._ids = self._cache = self._grid = None

    def set_local(self, robots: set[RobotId], courier: Courier | None = None) -> None:
        """Only ``robots`` move in this process; the others' motions are only seen.

        For a simulation spread over processes: a motion of another process's robot
        comes in through :meth:`see_motion`, at the instant it is seen here; the
        ledger keeps the items of ``robots`` only (items come and go, see
        :class:`ItemLedger`), and ``courier`` takes a hand-over's steps to the other
        robots (their processes call :meth:`item_arrives` and :meth:`item_receipt`).

        Raises:
            UnknownRobotError: a robot of ``robots`` is not in the environment.
            SimulationError: items were made already (the ledger must start partial).
        """
        for robot_id in robots:
            self._robot(robot_id)
        if self._items.created or self._items.events:
            raise SimulationError("set the local robots before any item is made")
        for robot_id, robot in self._robots.items():
            robot.local = robot_id in robots
        self._items = ItemLedger(partial=True)
        self._courier = courier

    def hide(self, robot_id: RobotId) -> None:
        """Another process's robot is out of this one's sight: it is nowhere, until shown.

        For a run across processes with an interaction range: a worker watches only the
        robots of the others that can come within range of its own. A hidden robot is
        in no range query and in range of nobody (its position is NaN); the motions
        it is seen to start meanwhile are kept (:meth:`see_motion`), not placed.

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: the robot is this process's own.
        """
        robot = self._robot(robot_id)
        if robot.local:
            raise SimulationError(f"robot {robot_id} runs here: only another's can be hidden")
        if robot.hidden:
            return
        robot.hidden = True
        self._table.blank(robot.index)
        if self._seen is not None:
            self._seen.blank(robot.index)
        if self._grid is not None:
            self._grid.remove(robot.index)
        self._cache = None

    def show(self, robot_id: RobotId) -> None:
        """A hidden robot is watched again: where the latest motion it was seen to start says.

        Raises:
            UnknownRobotError: no such robot.
        """
        robot = self._robot(robot_id)
        if not robot.hidden:
            return
        robot.hidden = False
        self._table.set(robot.index, robot.since, robot.motion)
        if self._seen is not None:
            assert robot.seen is not None
            self._seen.set(robot.index, robot.seen_since, robot.seen)
            motion = robot.seen
        else:
            motion = robot.motion
        if self._grid is not None:
            self._grid.place(
                robot.index, motion.start.x, motion.start.y, motion.end.x, motion.end.y
            )
        self._cache = None

    def is_hidden(self, robot_id: RobotId) -> bool:
        """Whether the robot is out of sight (see :meth:`hide`)."""
        return self._robot(robot_id).hidden

    def is_mobile(self, robot_id: RobotId) -> bool:
        """Whether the robot can move (see :meth:`add_robot`)."""
        return self._robot(robot_id).mobile

    def _robot(self, robot_id: RobotId) -> RobotEntry:
        try:
            return self._robots[robot_id]
        except KeyError:
            raise UnknownRobotError(f"robot {robot_id} is not in the environment") from None

    def _robot_at(self, robot_id: RobotId, t: float) -> RobotEntry:
        """The robot, to be asked about instant ``t`` (checked)."""
        robot = self._robot(robot_id)
        check_instant(t)
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
        top = robot.top_speed
        if (
            top is not None
            and motion.profile is not None
            and motion.profile.top_speed() > top * _SPEED_TOLERANCE
        ):
            raise SimulationError(
                f"robot {robot_id}: a motion at up to {motion.profile.top_speed():g} units/s, "
                f"faster than its top speed of {top:g} (Environment.add_robot)"
            )
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
        seen = self._seen
        if seen is None:
            if self._grid is not None:
                # The robot is on this segment at every instant from now on.
                self._grid.place(
                    robot.index, motion.start.x, motion.start.y, motion.end.x, motion.end.y
                )
        elif robot.local:  # the others see it once the latency has passed
            robot.motions += 1
            self._at(
                start_time + self.latency,
                (MOTION, robot_id, robot.motions),
                lambda: self._see_own(robot, robot_id, motion, start_time),
            )
        self._cache = None
        for watcher in self._motion_watchers:
            watcher(robot_id, motion, start_time)

    def see_motion(self, robot_id: RobotId, motion: Motion, start_time: float) -> None:
        """The others see the robot's motion that started at ``start_time`` from now on.

        Called once its latency has passed: by the environment itself for its own
        robots, and by whoever brings another process's motions for the others (it
        is then also their motion here, see :meth:`set_local`). Without a latency,
        motions are seen as they start and this only starts the motion.

        Raises:
            UnknownRobotError: no such robot.
            SimulationError: as :meth:`start_motion`, for another process's robot.
        """
        robot = self._robot(robot_id)
        seen = self._seen
        if seen is None:
            if not robot.local:
                self.start_motion(robot_id, motion, start_time)
            return
        if not robot.local:  # it is here what it is seen to be: no more is known of it
            robot.odometer = robot.travelled(start_time)
            robot.motion, robot.since = motion, start_time
            if not robot.hidden:
                self._table.set(robot.index, start_time, motion)
                self._cache = None
        robot.seen, robot.seen_since = motion, start_time
        if robot.hidden:  # kept for when it is shown again
            return
        seen.set(robot.index, start_time, motion)
        if self._grid is not None:
            self._grid.place(
                robot.index, motion.start.x, motion.start.y, motion.end.x, motion.end.y
            )

    def _see_own(self, robot: RobotEntry, robot_id: RobotId, motion: Motion, start: float) -> None:
        if self._robots.get(robot_id) is robot:  # else removed since: nobody to see any more
            self.see_motion(robot_id, motion, start)

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

    def top_speed(self, robot_id: RobotId) -> float | None:
        """The fastest the robot may translate (see :meth:`add_robot`); ``None``: unbounded."""
        return self._robot(robot_id).top_speed

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
        check_instant(t)
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
                or wider than the interaction range; or ``t`` is NaN.
        """
        index = self._robot(robot_id).index
        if not radius >= 0:
            raise SimulationError(f"radius must be >= 0, got {radius!r}")
        limit = self.interaction_range
        if limit is not None and radius > limit:
            raise SimulationError(
                f"robot {robot_id} asked for the robots within {radius:g}; this run's "
                f"interaction range is {limit:g} ([network] range): ask within it"
            )
        check_instant(t)
        seen = self._seen
        here = self._table.position(index, t)  # the asker where it is
        near = self._near(index, here, radius)
        if near is None:
            if seen is None:
                everyone = self.positions_at(t)
                return nearest_first(everyone.ids, everyone.xy, everyone.xy[index], radius, index)
            xy = seen.positions(t)
            xy[index] = here
            return nearest_first(self._row_ids(), xy, xy[index], radius, index)
        rows = np.fromiter((index, *near), dtype=np.intp, count=len(near) + 1)
        if seen is None:
            xy = self._table.positions_of(t, rows)
        else:  # the others where they are seen
            xy = seen.positions_of(t, rows)
            xy[0] = here
        return nearest_first(self._row_ids()[rows], xy, xy[0], radius, 0)

    def in_range(self, robot_id: RobotId, other: RobotId, t: float) -> bool:
        """Whether ``robot_id`` reaches ``other`` at ``t``: what :meth:`within` would say.

        ``other`` is within the interaction range of ``robot_id`` (inclusive), the
        asker where it is and the other where it is seen (with a latency), with the
        very arithmetic of :meth:`within`: a datagram reaches exactly the robots a
        range query would list. Always true without an interaction range.

        Raises:
            UnknownRobotError: either robot is not in the environment.
            SimulationError: ``t`` is NaN.
        """
        limit = self.interaction_range
        index, there = self._robot(robot_id).index, self._robot(other).index
        if limit is None:
            return True
        check_instant(t)
        seen = self._seen
        table = self._table if seen is None else seen
        x, y = self._table.position(index, t)  # the asker where it is
        other_x, other_y = table.position(there, t)
        dx, dy = other_x - x, other_y - y
        squared, bound = dx * dx + dy * dy, limit * limit
        if abs(squared - bound) > _CLOSE_CALL * bound:  # clear either way (NaN: not clear)
            return squared <= bound
        # At the edge: within's own arithmetic, which may round its sum otherwise.
        rows = np.array((index, there), dtype=np.intp)
        xy = table.positions_of(t, rows)
        xy[0] = (x, y)
        return bool(nearest_first(self._row_ids()[rows], xy, xy[0], limit, 0).ids.size)

    def _near(self, index: int, here: tuple[float, float], radius: float) -> set[int] | None:
        """Rows that may be within ``radius`` of row ``index``, at ``here``, itself left out.

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
        x, y = here
        box = (x - radius, y - radius, x + radius, y + radius)
        if grid.cells_over(*box) > len(self._robots):
            return None
        near = grid.rows_near(*box)
        near.discard(index)
        return near

    def _build_grid(self, cell: float) -> CellGrid:
        grid = CellGrid(cell)
        seen = self._seen is not None  # then the grid files where the others are seen
        for robot in self._robots.values():
            motion = robot.seen if seen and robot.seen is not None else robot.motion
            grid.place(robot.index, motion.start.x, motion.start.y, motion.end.x, motion.end.y)
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
        check_instant(t)
        return {robot_id: robot.travelled(t) for robot_id, robot in self._robots.items()}
