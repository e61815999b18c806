"""What a run observes of its robots, window by window, in the same order however they are spread.

With a network latency ``L`` a run moves in windows of simulated time (see
:mod:`._windows`): every robot runs every event before the window's end, then the
window closes. The robots' Environment is then ahead of the window's instants (a
robot may have started a motion after the instant of a sample), and in a run
across processes it holds only some robots. So the run observes a *mirror* of it
instead: an Environment with every robot, to which each window's motions and item
events are applied in one fixed order, the same in every process and for any
number of processes: by instant, then robot, then that robot's own count. The
trace is sampled from the mirror between the events, the mission's objective
follows the mirror's ledger and motions, and an exchange's snapshot sees the
mirror just after it. A run across processes therefore writes the very trace
of a run in one process.

:class:`Observation` is the record of one window: what one process's robots did
in it. :class:`Recorder` makes it from an Environment's robots (subscribed to
their motions and items); :class:`Observer` applies the records of every process.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable, Iterable
from typing import Final

import msgspec

from ..._errors import SimulationError
from ..._types import RobotId
from ...sim._environment import Environment
from ...sim._item_events import ItemEvent, ItemEventKind
from ...sim._kinematics import Motion

__all__ = ["ItemRecord", "MotionRecord", "Observation", "Observer", "Recorder", "mirror_of"]

_MOTION: Final = 0
_ITEM: Final = 1


class MotionRecord(msgspec.Struct, frozen=True, array_like=True):
    """A motion a robot started: at ``t``, its ``n``-th, as numbers (see ``Motion.to_numbers``)."""

    t: float
    robot: RobotId
    n: int
    numbers: list[float]


class ItemRecord(msgspec.Struct, frozen=True, array_like=True):
    """An item event in a robot's hands: at ``t``, its ``n``-th (see :class:`ItemEvent`)."""

    t: float
    actor: RobotId
    n: int
    kind: str
    item: int
    robot: RobotId
    receiver: RobotId | None

    def event(self) -> ItemEvent:
        """The ledger's event this records."""
        return ItemEvent(self.t, ItemEventKind(self.kind), self.item, self.robot, self.receiver)


class Observation(msgspec.Struct, array_like=True):
    """What one process's robots did in one window: their motions and item events."""

    motions: list[MotionRecord] = msgspec.field(default_factory=list)
    items: list[ItemRecord] = msgspec.field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.motions or self.items)

    def before(self, horizon: float) -> tuple[Observation, Observation]:
        """The records before ``horizon``, and those at or after it."""
        return (
            Observation(
                [m for m in self.motions if m.t < horizon],
                [i for i in self.items if i.t < horizon],
            ),
            Observation(
                [m for m in self.motions if m.t >= horizon],
                [i for i in self.items if i.t >= horizon],
            ),
        )

    def split(self, horizon: float) -> tuple[Observation, Observation]:
        """The records at or before ``horizon``, and the later ones."""
        return (
            Observation(
                [m for m in self.motions if m.t <= horizon],
                [i for i in self.items if i.t <= horizon],
            ),
            Observation(
                [m for m in self.motions if m.t > horizon],
                [i for i in self.items if i.t > horizon],
            ),
        )


class Recorder:
    """Records what an Environment's own robots do, for the run's :class:`Observer`.

    Args:
        environment: the robots' Environment (its local robots' motions and items).
        robots: the robots whose motions are recorded (the others' are only seen).
        keep: also keep each motion itself in :attr:`kept`, for an Observer in this
            process (which then need not rebuild it from its numbers).
    """

    def __init__(
        self, environment: Environment, robots: Iterable[RobotId], *, keep: bool = False
    ) -> None:
        self._robots = set(robots)
        self.kept: dict[tuple[RobotId, int], Motion] | None = {} if keep else None
        """With ``keep``: the motions recorded and not applied yet, by robot and count."""
        # Per robot: its motions (as the Environment counts them, for when they are seen)
        # and its item events.
        self._motions: dict[RobotId, int] = {}
        self._items: dict[RobotId, int] = {}
        self._window = Observation()
        environment.watch_motions(self._moved)
        environment.items.subscribe(self._item)

    def take(self) -> Observation:
        """What was recorded since the last call."""
        window, self._window = self._window, Observation()
        return window

    @staticmethod
    def _count(counts: dict[RobotId, int], robot: RobotId) -> int:
        n = counts.get(robot, 0) + 1
        counts[robot] = n
        return n

    def _moved(self, robot: RobotId, motion: Motion, start: float) -> None:
        if robot in self._robots:
            n = self._count(self._motions, robot)
            self._window.motions.append(MotionRecord(start, robot, n, motion.to_numbers()))
            if self.kept is not None:
                self.kept[robot, n] = motion

    def _item(self, event: ItemEvent) -> None:
        actor = event.actor
        self._window.items.append(
            ItemRecord(
                event.t,
                actor,
                self._count(self._items, actor),
                event.kind.value,
                event.item,
                event.robot,
                event.receiver,
            )
        )


class Observer:
    """Applies every process's windows to the mirror, sampling it on the way (see the module docs).

    Args:
        mirror: an Environment with every robot, standing where it starts, and
            no latency (see :func:`mirror_of`): what the run's objective and
            trace read.
        interval: simulated seconds between two samples.
        sample: awaited at each sample instant, once the mirror is there.
        done: whether the run is over (its mission complete): nothing after the
            event that ended it is applied.
        kept: the motions a :class:`Recorder` of this process kept (``keep=True``):
            each is applied as it is, and taken out, instead of being rebuilt from
            its numbers (the same motion, to the bit; rebuilding costs about 13 µs).
    """

    def __init__(
        self,
        mirror: Environment,
        interval: float,
        sample: Callable[[float], Awaitable[None]],
        done: Callable[[], bool],
        kept: dict[tuple[RobotId, int], Motion] | None = None,
    ) -> None:
        self.mirror = mirror
        self._kept = kept
        self._interval = interval
        self._sample = sample
        self._done = done
        self._tick = 0  # the next sample is at tick * interval
        self.until = 0.0
        """The instant up to which the mirror is complete: the last window's end."""
        self.completed_at: float | None = None
        """The instant of the record whose event completed the mission, once one did."""

    @property
    def next_sample(self) -> float:
        """The instant of the next sample."""
        return self._tick * self._interval

    async def window(self, end: float, observations: Iterable[Observation]) -> None:
        """Applies a window's records (every process's), in order; samples before ``end``."""
        done = self._done
        for t, kind, robot, record in _in_order(observations):
            if done():
                return
            await self.sample_until(t, inclusive=False)
            self._apply(t, kind, robot, record)
            if done():
                self.completed_at = t
        if not done():
            await self.sample_until(end, inclusive=False)
        self.until = end

    def apply(self, observations: Iterable[Observation], until: float | None = None) -> None:
        """Applies records at once, in order, without sampling (on scaled time, a clock does).

        ``until``: the instant up to which the mirror is then complete, if known.
        """
        done = self._done
        for t, kind, robot, record in _in_order(observations):
            if done():
                break
            self._apply(t, kind, robot, record)
        if until is not None and not done():
            self.until = max(self.until, until)

    def _apply(
        self, t: float, kind: int, robot: RobotId, record: MotionRecord | ItemRecord
    ) -> None:
        if kind == _MOTION:
            assert isinstance(record, MotionRecord)
            kept = None if self._kept is None else self._kept.pop((robot, record.n), None)
            motion = Motion.from_numbers(record.numbers) if kept is None else kept
            self.mirror.start_motion(robot, motion, t)
        else:
            assert isinstance(record, ItemRecord)
            self.mirror.items.apply(record.event())

    async def sample_until(self, t: float, *, inclusive: bool) -> None:
        """Takes every sample before ``t`` (and at ``t``, if ``inclusive``) not taken yet."""
        while True:
            at = self._tick * self._interval
            if at > t or (at == t and not inclusive) or math.isinf(at):
                return
            self._tick += 1
            await self._sample(at)
            self.until = max(self.until, at)


def _in_order(
    observations: Iterable[Observation],
) -> list[tuple[float, int, RobotId, MotionRecord | ItemRecord]]:
    """Every record of ``observations``, by instant, kind, robot, then the robot's own count."""
    records: list[tuple[float, int, RobotId, int, MotionRecord | ItemRecord]] = []
    for observation in observations:
        records.extend((m.t, _MOTION, m.robot, m.n, m) for m in observation.motions)
        records.extend((i.t, _ITEM, i.actor, i.n, i) for i in observation.items)
    records.sort(key=lambda record: record[:4])
    return [(t, kind, robot, record) for t, kind, robot, _, record in records]


def mirror_of(environment: Environment) -> Environment:
    """An Environment with ``environment``'s robots as they stand, no latency, items by creator.

    What a run with a latency observes (see :class:`Observer`): built once the
    application placed its robots, before they start.

    Raises:
        SimulationError: a robot is moving already.
    """
    mirror = Environment()
    for robot_id in environment.robot_ids:
        motion, since = environment.motion_of(robot_id)
        if since != -math.inf or motion.end != motion.start:
            raise SimulationError(
                f"robot {robot_id} moves before the run starts: a run observes robots "
                "that stand where the application placed them"
            )
        mirror.add_robot(robot_id, motion.end, mobile=environment.is_mobile(robot_id))
    return mirror
