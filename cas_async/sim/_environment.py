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

With a ``latency`` (the simulation's network model: the least simulated time any
effect needs to go from one robot to another), a robot's motion is *seen* by the
others only ``latency`` after it started: range queries (:meth:`within`) place the
asker where it really is and every other robot where its last motion seen says it
is, the motion it was on ``latency`` ago carried on to now (dead reckoning, as a
robot does with a neighbour's last broadcast). The motions seen change at their
instants in a fixed order (see :mod:`cas_async._deliveries`), so what a robot
senses does not depend on which robots share its process. Item hand-overs take
the latency too (see :meth:`hand_over`).
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Protocol

import numpy as np
import numpy.typing as npt

from .._clock import Clock
from .._deliveries import ITEM, MOTION, RECEIPT, Deliveries
from .._errors import ConfigurationError, SimulationError, UnknownRobotError
from .._pose import Pose
from .._positions import Positions
from .._types import ItemId, RobotId
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
    local: bool = True  # its motions start here (else they are only seen, see see_motion)
    motions: int = 0  # motions started so far: their order within an instant
    sent: int = 0  # items sent so far, and answers given: their order within an instant
    seen: Motion | None = None  # with a latency: the motion the others see
    seen_since: float = -math.inf

    def travelled(self, t: float) -> float:
        """Total distance translated up to instant ``t``."""
        # A standing motion (the only kind that starts at -inf) translates nothing;
        # skipping it also avoids evaluating inf - inf.
        if self.motion.length == 0:
            return self.odometer
        return self.odometer + self.motion.travelled(t - self.since)


class Courier(Protocol):
    """Takes a hand-over's steps to robots of other processes (see ``Environment.set_local``)."""

    def arrive(
        self,
        at: float,
        item: ItemId,
        giver: RobotId,
        receiver: RobotId,
        sent: float,
        reach: float,
        n: int,
    ) -> None:
        """The item reaches ``receiver`` (another process's robot) at ``at``."""

    def receipt(
        self,
        at: float,
        item: ItemId,
        giver: RobotId,
        receiver: RobotId,
        n: int,
        refused: str | None,
        answer: int,
    ) -> None:
        """The answer to hand-over ``n`` reaches ``giver`` (another process's robot) at ``at``.

        ``answer`` is the receiver's own count of answers: their order within an instant.
        """


class Environment:
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

    Raises:
        ValueError: ``cell_size`` is not a finite number > 0, ``latency`` is not a
            finite number >= 0, or a latency comes without a clock.
    """

    def __init__(
        self,
        *,
        cell_size: float | None = None,
        latency: float = 0.0,
        clock: Clock | None = None,
    ) -> None:
        if cell_size is not None and not (math.isfinite(cell_size) and cell_size > 0):
            raise ValueError(f"cell_size must be a finite number > 0, got {cell_size!r}")
        if not (math.isfinite(latency) and latency >= 0):
            raise ValueError(f"latency must be a finite number >= 0, got {latency!r}")
        if latency > 0 and clock is None:
            raise ValueError("an Environment with a latency needs the robots' clock")
        self.latency = latency
        """Simulated seconds before others see a motion, and a handed item arrives."""
        self._clock = clock
        self._robots: dict[RobotId, _Robot] = {}
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
        self._robots[robot_id] = _Robot(index, mobile, motion, -math.inf, seen=motion)
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
            self._table.set(robot.index, start_time, motion)
            self._cache = None
        robot.seen, robot.seen_since = motion, start_time
        seen.set(robot.index, start_time, motion)
        if self._grid is not None:
            self._grid.place(
                robot.index, motion.start.x, motion.start.y, motion.end.x, motion.end.y
            )

    def _see_own(self, robot: _Robot, robot_id: RobotId, motion: Motion, start: float) -> None:
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
        seen = self._seen
        near = self._near(index, radius, t)
        if near is None:
            if seen is None:
                everyone = self.positions_at(t)
                return _nearest_first(everyone.ids, everyone.xy, everyone.xy[index], radius, index)
            xy = seen.positions(t)
            xy[index] = self._table.positions_of(t, np.array([index], dtype=np.intp))[0]
            return _nearest_first(self._row_ids(), xy, xy[index], radius, index)
        rows = np.fromiter((index, *near), dtype=np.intp, count=len(near) + 1)
        if seen is None:
            xy = self._table.positions_of(t, rows)
        else:  # the asker where it is, the others where they are seen
            xy = seen.positions_of(t, rows)
            xy[0] = self._table.positions_of(t, rows[:1])[0]
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

    async def send_item(
        self, item: ItemId, giver: RobotId, receiver: RobotId, t: float, *, reach: float
    ) -> None:
        """Hands ``item`` from ``giver`` to ``receiver`` over the latency: returns once it is known.

        With a latency ``L`` (see the module docs) the item leaves the giver at ``t``
        and reaches the receiver at ``t + L``. It is taken there if the receiver's
        hands are held out to the giver then and the two are within ``reach`` (the
        receiver where it is, the giver where it is seen); else it travels back and
        is the giver's again at ``t + 2L``. The giver learns the outcome at ``t + 2L``
        either way: this returns then, or raises ``SimulationError`` saying why the
        receiver refused it. Without a latency it is :meth:`hand_over`.

        Raises:
            UnknownRobotError: either robot is not in the environment.
            SimulationError: ``reach`` is negative or NaN, ``t`` is not finite, the
                giver does not hold the item, or the receiver refused it.
        """
        if self._seen is None:
            self.hand_over(item, giver, receiver, t, reach=reach)
            return
        self._robot(receiver)
        if not reach >= 0:
            raise SimulationError(f"reach must be >= 0, got {reach!r}")
        if not math.isfinite(t):
            raise SimulationError(f"a hand-over's t must be a finite number, got {t!r}")
        self._items.send(item, giver, receiver, t)
        entry = self._robot(giver)
        entry.sent += 1
        n = entry.sent
        outcome: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._sending[(giver, n)] = outcome
        at = t + self.latency
        if self._robot(receiver).local:
            self._at(
                at, (ITEM, giver, n), lambda: self.item_arrives(item, giver, receiver, t, reach, n)
            )
        else:
            assert self._courier is not None  # set_local() gave one with the remote robots
            self._courier.arrive(at, item, giver, receiver, t, reach, n)
        try:
            await outcome
        finally:
            self._sending.pop((giver, n), None)

    def item_arrives(
        self, item: ItemId, giver: RobotId, receiver: RobotId, sent: float, reach: float, n: int
    ) -> None:
        """Hand-over ``n`` of ``giver`` (sent at ``sent``) reaches ``receiver`` now, ``sent + L``.

        Taken or refused here (see :meth:`send_item`); the answer goes back to the giver.
        On scaled real time a hand-over that comes late (from another process) is
        taken when it came, never before what was recorded since.
        """
        t = sent + self.latency
        clock = self._clock
        if clock is not None and not clock.is_virtual:
            t = max(t, clock.now())
        refused = self._refusal(item, giver, receiver, t, reach)
        giver_here = self._robot(giver).local
        if refused is None:
            self._items.arrive(item, giver, receiver, t)
        else:
            self._items.refuse(item, giver, receiver, t)
            if not giver_here:  # on its way back to the other process's ledger
                self._items.handed_away(item)
        entry = self._robot(receiver)
        entry.sent += 1
        at = t + self.latency
        if giver_here:
            self._at(
                at,
                (RECEIPT, receiver, entry.sent),
                lambda: self.item_receipt(item, giver, receiver, n, refused),
            )
        else:
            assert self._courier is not None
            self._courier.receipt(at, item, giver, receiver, n, refused, entry.sent)

    def item_receipt(
        self, item: ItemId, giver: RobotId, receiver: RobotId, n: int, refused: str | None
    ) -> None:
        """The answer to ``giver``'s hand-over ``n`` reaches it now: the item is back if refused."""
        taker = self._robots.get(receiver)  # (gone since it took the item: it was here)
        if refused is not None:
            self._items.returned(item, giver, self._robot_time(giver))
        elif taker is not None and not taker.local:
            self._items.handed_away(item)  # it is the other process's ledger's now
        outcome = self._sending.get((giver, n))
        if outcome is not None and not outcome.done():
            if refused is None:
                outcome.set_result(None)
            else:
                outcome.set_exception(SimulationError(refused))

    def _refusal(
        self, item: ItemId, giver: RobotId, receiver: RobotId, t: float, reach: float
    ) -> str | None:
        """Why ``receiver`` refuses ``item`` from ``giver`` arriving at ``t``, or ``None``."""
        accepting = self._robot(receiver).accepting
        if accepting is not None and giver not in accepting:
            return (
                f"robot {receiver} does not take items from robot {giver} at {t!r}"
                f" (it takes them from {sorted(accepting)})"
            )
        here = self.pose_at(receiver, t)
        seen = self._seen
        assert seen is not None
        x, y = seen.positions_of(t, np.array([self._robot(giver).index], dtype=np.intp))[0].tolist()
        distance = math.hypot(here.x - x, here.y - y)
        if distance > reach:
            return (
                f"robot {giver} at ({x!r}, {y!r}) cannot hand item {item} to robot {receiver} "
                f"at ({here.x!r}, {here.y!r}) at {t!r}: they are {distance!r} apart, beyond "
                f"the reach of {reach!r}"
            )
        return None

    def _robot_time(self, robot_id: RobotId) -> float:
        """Now, in simulated time (what the clock says)."""
        assert self._clock is not None
        return self._clock.now()

    def _at(self, t: float, key: tuple[object, ...], action: Callable[[], None]) -> None:
        """Runs ``action`` at simulated instant ``t``, in ``key`` order (see ``_deliveries``)."""
        assert self._clock is not None  # a latency comes with a clock
        Deliveries.of().at(self._clock.loop_time_at(t), key, action)

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
