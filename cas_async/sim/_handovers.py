"""Items changing hands in the Environment: at once, or over the network's latency.

Part of :class:`~cas_async.sim.Environment` (its items, kept apart for size): robots
create items, hand them over and retire them, and the
:class:`~cas_async.sim._items.ItemLedger` checks that none is ever lost or held
twice. Without a latency a hand-over is atomic (:meth:`Handovers.hand_over`); with
one (:meth:`Handovers.send_item`) the item leaves the giver at ``t``, reaches the
receiver at ``t + L`` (taken, or refused), and the answer reaches the giver at
``t + 2L``; the receiver may be another process's robot (a :class:`Courier` takes
the steps there).
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable

from .._body._pose import Pose
from .._errors import SimulationError
from .._time._clock import Clock
from .._time._deliveries import ITEM, RECEIPT, Deliveries
from .._types import ItemId, RobotId
from ._entries import Courier, RobotEntry
from ._items import ItemLedger
from ._segments import SegmentTable

__all__ = ["Handovers"]


class Handovers:
    """The items part of the Environment (a base of :class:`~cas_async.sim.Environment`).

    It reads the Environment's robots and what they see; the Environment sets
    these attributes and provides ``_robot`` and ``pose_at``.
    """

    latency: float
    interaction_range: float | None
    _robots: dict[RobotId, RobotEntry]
    _clock: Clock | None
    _items: ItemLedger
    _sending: dict[tuple[RobotId, int], asyncio.Future[None]]
    _courier: Courier | None
    _seen: SegmentTable | None

    def _robot(self, robot_id: RobotId) -> RobotEntry:
        raise NotImplementedError  # the Environment's

    def _check_reach(self, giver: RobotId, reach: float) -> None:
        """Refuses a negative or NaN reach, and one beyond the interaction range."""
        if not reach >= 0:
            raise SimulationError(f"reach must be >= 0, got {reach!r}")
        limit = self.interaction_range
        if limit is not None and reach > limit:
            raise SimulationError(
                f"robot {giver} hands an item over a reach of {reach:g}, beyond this run's "
                f"interaction range of {limit:g} ([network] range): nothing reaches farther"
            )

    def pose_at(self, robot_id: RobotId, t: float) -> Pose:
        """The robot's pose at instant ``t`` (the Environment's)."""
        raise NotImplementedError

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
        self._check_reach(giver, reach)
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
        self._check_reach(giver, reach)
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
        x, y = seen.position(self._robot(giver).index, t)
        distance = math.hypot(here.x - x, here.y - y)
        # Not "distance > reach": a giver another process does not watch (a run across
        # processes with an interaction range) is nowhere, NaN, and out of reach. The
        # message names where the receiver is, which every process knows alike.
        if not distance <= reach:
            return (
                f"robot {giver} cannot hand item {item} to robot {receiver} at "
                f"({here.x!r}, {here.y!r}) at {t!r}: it is beyond the reach of {reach!r}"
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
