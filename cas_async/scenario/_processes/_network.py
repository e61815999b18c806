"""The robots of one worker process, and the road to the robots of the others.

A worker of a run across processes runs its share of the robots. They talk to
each other as on a :class:`~cas_async.MemoryTransport` with the run's latency: a
datagram sent at ``t`` reaches its receiver at ``t + L``, in the fixed order of
:mod:`cas_async._time._deliveries`. What they send to another process's robots, and
the steps of their hand-overs with them (see :meth:`Environment.send_item`), go
out as :class:`~._control.Remote` effects, each due at its instant: on virtual
time with the worker's window (:class:`~._control.Window`), on scaled time at
once. What comes in from the other processes is scheduled the same way, so a
robot cannot tell whether the robot it talks to shares its process.

Membership is the run's: every robot of the run is known from the start (the
world says which process runs which), none joins or leaves. With an interaction
range, the worker watches only the other processes' robots that can come within
range of its own (:meth:`ProcessNetwork.watch`, see :mod:`._halo`): the motions of
the others are kept, not applied, until they come into sight.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Iterable, Mapping
from functools import partial
from typing import final

from ..._core._transport_contract import DatagramSink, Endpoint, Transport
from ..._errors import ConfigurationError, RobotStateError, SimulationError, UnknownRobotError
from ..._time._clock import Clock
from ..._time._deliveries import DATAGRAM, ITEM, MOTION, RECEIPT, Deliveries
from ..._types import Address, ItemId, RobotId
from ..._wire._codec import DEFAULT_MAX_DATAGRAM
from ...sim._environment import Environment
from ...sim._kinematics import Motion
from ._control import Remote
from ._observer import MotionRecord, Observation

__all__ = ["ProcessNetwork"]


@final
class _Endpoint(Endpoint):
    """A local robot's attachment to its process's network."""

    __slots__ = ("_closed", "_network", "_sent", "_sink", "max_datagram_size", "robot_id")

    def __init__(self, network: ProcessNetwork, robot_id: RobotId, sink: DatagramSink) -> None:
        self._network = network
        self._sink = sink
        self._closed = False
        self._sent = 0  # this robot's datagrams so far: their order within an instant
        self.robot_id = robot_id
        self.max_datagram_size = DEFAULT_MAX_DATAGRAM

    @property
    def address(self) -> Address:
        return ("process", self.robot_id)

    @property
    def sink(self) -> DatagramSink:
        """Where this robot's datagrams go."""
        return self._sink

    def send(self, robot_id: RobotId, data: bytes) -> None:
        if self._closed:
            raise RobotStateError(f"robot {self.robot_id}: endpoint is closed")
        self._sent += 1
        self._network.carry(self.robot_id, self._sent, robot_id, data)

    def receive(self, data: bytes, sender: RobotId) -> None:
        """A datagram whose latency is over: to the sink (also after close: it counts it)."""
        self._sink.datagram_received(data, sender)

    def peers(self) -> Iterable[RobotId]:
        return [rid for rid in self._network.robots if rid != self.robot_id]

    def knows(self, robot_id: RobotId) -> bool:
        return robot_id in self._network.robots

    def close(self) -> None:
        self._closed = True


@final
class ProcessNetwork(Transport):
    """A worker's robots, and their road to the other processes' robots (see the module docs).

    Args:
        owners: every robot of the run, by the process (worker index) that runs it.
        index: this worker's index.
        latency: the run's latency, simulated seconds (> 0).
        clock: the robots' clock.
        environment: the worker's Environment (its local robots set, see
            :meth:`Environment.set_local`): hand-overs with other processes'
            robots go through :meth:`arrive` and :meth:`receipt`.
        flush: called once when there is something to send to other processes,
            on scaled time (on virtual time the window takes it).
    """

    supports_virtual_time = True

    def __init__(
        self,
        owners: Mapping[RobotId, int],
        index: int,
        latency: float,
        clock: Clock,
        environment: Environment,
        flush: Callable[[], None] | None = None,
    ) -> None:
        self.robots = dict(sorted(owners.items()))  # by id: peers() as MemoryTransport's
        self._index = index
        self._latency = latency
        self._clock = clock
        self._environment = environment
        self._flush = flush
        self._virtual = flush is None  # on virtual time windows carry what goes out
        self._local: dict[RobotId, _Endpoint] = {}
        self._outgoing: list[Remote] = []
        self._others = sum(1 for owner in self.robots.values() if owner != index)
        self._hidden: set[RobotId] = set()  # the others' robots out of sight
        self._unseen: dict[RobotId, MotionRecord] = {}  # the latest motion of each, unapplied
        self.applied = 0
        """The others' motions applied so far (seen by this worker's robots)."""
        self.sent = 0
        """Effects sent to other processes so far."""
        self.received = 0
        """Effects received from other processes so far."""

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        """Attaches one of this process's robots.

        Raises:
            ConfigurationError: the robot is another process's, or attached already.
        """
        if self.robots.get(robot_id) != self._index:
            raise ConfigurationError(f"robot {robot_id} is not run by worker {self._index}")
        if robot_id in self._local:
            raise ConfigurationError(f"robot {robot_id} is already attached")
        endpoint = self._local[robot_id] = _Endpoint(self, robot_id, sink)
        return endpoint

    # -- out ----------------------------------------------------------------------------

    def carry(self, sender: RobotId, n: int, receiver: RobotId, data: bytes) -> None:
        """Takes datagram ``n`` of ``sender`` to ``receiver``, due ``latency`` from now."""
        at = self._clock.loop_time_at(self._clock.now() + self._latency)
        target = self._local.get(receiver)
        if target is not None:
            Deliveries.of().at(at, (DATAGRAM, sender, n), lambda: target.receive(data, sender))
        elif receiver in self.robots:
            self._out(Remote(at, DATAGRAM, sender, n, receiver, data))
        else:
            raise UnknownRobotError(f"no robot {receiver} in this run")

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
        """A hand-over's item goes to another process's robot (see ``Environment.set_local``)."""
        loop_at = self._clock.loop_time_at(at)
        self._out(Remote(loop_at, ITEM, giver, n, receiver, item=item, sent=sent, reach=reach))

    def receipt(
        self,
        at: float,
        item: ItemId,
        giver: RobotId,
        receiver: RobotId,
        n: int,
        refused: str | None,
        answer: int = 0,
    ) -> None:
        """A hand-over's answer goes back to another process's giver."""
        loop_at = self._clock.loop_time_at(at)
        self._out(
            Remote(loop_at, RECEIPT, receiver, answer, giver, item=item, answer=n, refused=refused)
        )

    def _out(self, remote: Remote) -> None:
        if not self._outgoing and self._flush is not None:
            self._flush()
        self._outgoing.append(remote)
        self.sent += 1

    def take_outgoing(self) -> list[Remote]:
        """What was sent to other processes since the last call."""
        outgoing, self._outgoing = self._outgoing, []
        return outgoing

    # -- in -----------------------------------------------------------------------------

    def receive(self, sender: int, observation: Observation, remotes: Iterable[Remote]) -> None:
        """Schedules what worker ``sender`` sent: its robots' motions seen, effects on ours.

        Each at its instant; on scaled time an instant already past comes at once.
        """
        if sender == self._index:
            return
        clock, latency = self._clock, self._latency
        now = asyncio.get_running_loop().time() if self._virtual else -math.inf
        for record in observation.motions:
            at = clock.loop_time_at(record.t + latency)
            if at <= now:  # a worker far behind: its robot stayed out of sight meanwhile
                self._keep_unseen(record)
                continue
            self._at(at, (MOTION, record.robot, record.n), partial(self._seen, record))
        for remote in remotes:
            if self.robots.get(remote.receiver) == self._index:
                self.received += 1
                self._at(remote.at, (remote.kind, remote.sender, remote.n), self._effect(remote))

    def _seen(self, record: MotionRecord) -> None:
        """Another process's robot is seen to start a motion: applied, or kept if out of sight."""
        robot = record.robot
        if robot in self._hidden:
            self._keep_unseen(record)
            return
        self.applied += 1
        self._environment.see_motion(robot, Motion.from_numbers(record.numbers), record.t)

    def _keep_unseen(self, record: MotionRecord) -> None:
        """An out-of-sight robot started a motion: the latest one it started is kept.

        Raises:
            SimulationError: the robot is in sight: its motion came too late to apply
                (a worker ran past what it heard; a fault of the protocol, never the app's).
        """
        robot = record.robot
        if robot not in self._hidden:
            raise SimulationError(
                f"worker {self._index}: the motion robot {robot} started at {record.t:g} came "
                "after its instant, with the robot in sight"
            )
        kept = self._unseen.get(robot)
        if kept is None or (kept.t, kept.n) < (record.t, record.n):
            self._unseen[robot] = record

    def watch(self, visible: Iterable[RobotId]) -> None:
        """From now on the others' robots in ``visible`` are in sight, the rest hidden.

        Called between two instants (at an epoch's start, before any of its events):
        a robot coming into sight is placed by the latest motion it was seen to start.
        """
        environment = self._environment
        sight = set(visible)
        others = {robot for robot, owner in self.robots.items() if owner != self._index}
        for robot in sorted(others - sight - self._hidden):
            environment.hide(robot)
            self._hidden.add(robot)
        for robot in sorted(self._hidden & sight):
            self._hidden.discard(robot)
            record = self._unseen.pop(robot, None)
            if record is not None:  # seen to start it meanwhile: that is where it is
                motion = Motion.from_numbers(record.numbers)
                environment.see_motion(robot, motion, record.t)
            environment.show(robot)

    @property
    def watched(self) -> int:
        """How many of the others' robots are in sight now."""
        return self._others - len(self._hidden)

    def _effect(self, remote: Remote) -> Callable[[], None]:
        environment = self._environment
        if remote.kind == DATAGRAM:
            target = self._local.get(remote.receiver)
            if target is None:  # not opened (yet, or any more): nobody to count it
                return lambda: None
            return lambda: target.receive(remote.data, remote.sender)
        if remote.kind == ITEM:
            return lambda: environment.item_arrives(
                remote.item, remote.sender, remote.receiver, remote.sent, remote.reach, remote.n
            )
        if remote.kind == RECEIPT:
            return lambda: environment.item_receipt(
                remote.item, remote.receiver, remote.sender, remote.answer, remote.refused
            )
        raise ValueError(f"no effect of kind {remote.kind}")

    def _at(self, at: float, key: tuple[object, ...], action: Callable[[], None]) -> None:
        # On scaled time one that came late runs at once, counted (Deliveries.late).
        Deliveries.of().at(at, key, action)
