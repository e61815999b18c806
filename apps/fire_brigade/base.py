"""What every Fire Brigade layer shares: its level names, the robot's kind and parameters.

The thesis (§5.4) adds an intermediate class between the framework's ``Layer``
and the application's layers, holding what they all need (the robot's type,
coordinates, bucket possession, trigonometry). :class:`BrigadeLayer` is that class.
Each layer keeps its own copy of the state it needs, kept up to date by messages.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Literal, overload

from cas_async import ConstantSpeed, Decelerating, Layer, Message

from .messages import Kind

__all__ = [
    "ACTION",
    "GOAL",
    "GROUP",
    "STRATEGY",
    "TASK",
    "BrigadeLayer",
    "Params",
    "Peers",
    "Point",
    "SinkSearch",
]

Point = tuple[float, float]

SinkSearch = Literal["everyone", "nearby"]
"""How a Generator finds the Sinks: it asks every robot, or the robots around it."""

GOAL, STRATEGY, GROUP, TASK, ACTION = range(5)
"""Levels of the five layers, top (0) to bottom (4)."""


class Peers(Sequence[int]):
    """Every robot of a roster but one, in roster order: a view, not a copy.

    A swarm of ``n`` robots gives each its peers; as tuples that would be ``n``
    squared ids in memory (800 MB for 10,000 robots), as views of one shared
    roster it is ``n``.

    Args:
        roster: every robot, each once (shared by all the views).
        at: the position in ``roster`` of the robot left out.

    Raises:
        IndexError: ``at`` is not a position in ``roster``.
    """

    __slots__ = ("_at", "_robot", "_roster")

    def __init__(self, roster: tuple[int, ...], at: int) -> None:
        if not 0 <= at < len(roster):
            raise IndexError(f"position {at} is not in a roster of {len(roster)} robots")
        self._roster = roster
        self._at = at
        self._robot = roster[at]

    def __len__(self) -> int:
        return len(self._roster) - 1

    @overload
    def __getitem__(self, index: int) -> int: ...
    @overload
    def __getitem__(self, index: slice) -> tuple[int, ...]: ...
    def __getitem__(self, index: int | slice) -> int | tuple[int, ...]:
        if isinstance(index, slice):
            return tuple(self)[index]
        size = len(self)
        if not -size <= index < size:
            raise IndexError(f"peer index {index} out of range for {size} peers")
        index %= size
        return self._roster[index + 1 if index >= self._at else index]

    def __iter__(self) -> Iterator[int]:
        roster, at = self._roster, self._at
        yield from roster[:at]
        yield from roster[at + 1 :]

    def __contains__(self, robot: object) -> bool:
        return robot != self._robot and robot in self._roster

    def __eq__(self, other: object) -> bool:
        """Equal to the tuple of the same ids (what peers were before they were a view)."""
        if isinstance(other, Peers | tuple):
            return len(other) == len(self) and all(a == b for a, b in zip(self, other, strict=True))
        return NotImplemented

    def __hash__(self) -> int:
        return hash(tuple(self))

    def __repr__(self) -> str:
        return f"Peers(roster of {len(self._roster)}, without {self._robot})"


@dataclass(frozen=True, slots=True)
class Params:
    """One robot's constants, the same in all of its layers.

    Attributes:
        kind: Generator, Sink or Transporter.
        peers: every other robot of the swarm (the roster, as a UDP directory has it),
            in roster order; the app builds :class:`Peers` views.
        world: the area's width and height.
        speed, deceleration, min_speed: a transporter's motion (see ``Transporters``).
        handover_time: seconds a hand-over takes.
        range: the partner search radius.
        search_step: how far a carrier moves toward its sink before looking again.
        retry_interval: a generator's wait before asking again after refusals.
        search_growth: a generator's search radius grows by this after each failed round.
        seed: seeds the layer's own random choices.
        timeout: seconds to wait for another robot before asking again.
        retries: times a question is asked again before the other robot counts as silent.
        patience: seconds a robot waits at a meeting point for a silent partner.
        sink_search: how a Generator finds the Sinks (see the Goal layer).
        reach: the run's interaction range (``[network] range``): no search looks
            farther, nor does it look past the world's diagonal (:attr:`farthest`).
    """

    kind: Kind
    peers: Sequence[int]
    world: Point
    speed: float
    deceleration: float
    min_speed: float
    handover_time: float
    range: float
    search_step: float
    retry_interval: float
    search_growth: float
    seed: int
    timeout: float = 0.5
    retries: int = 6
    patience: float = 30.0
    sink_search: SinkSearch = "everyone"
    reach: float = math.inf
    _empty: ConstantSpeed = field(init=False, repr=False, compare=False)
    _carrying: Decelerating = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # Made once: a profile works out its phases once, and layers ask for these often.
        object.__setattr__(self, "_empty", ConstantSpeed(self.speed))
        object.__setattr__(self, "_carrying", self._carrying_from(self.speed))

    @property
    def give_up_after(self) -> float:
        """Seconds after which a question asked ``retries`` times more is given up."""
        return (self.retries + 1) * self.timeout

    @property
    def farthest(self) -> float:
        """The widest a search goes: the world's diagonal, or the interaction range."""
        return min(math.hypot(*self.world), self.reach)

    @property
    def mobile(self) -> bool:
        """Only transporters move."""
        return self.kind is Kind.TRANSPORTER

    def empty(self) -> ConstantSpeed:
        """A transporter's motion without a bucket: full speed."""
        return self._empty

    def carrying(self, speed_now: float | None = None) -> Decelerating:
        """A transporter's motion with a bucket, slowing from ``speed_now`` (default: full).

        The one place fatigue is defined: the Action layer moves by it and the upper
        layers estimate with it.
        """
        return self._carrying if speed_now is None else self._carrying_from(speed_now)

    def _carrying_from(self, start: float) -> Decelerating:
        return Decelerating(start, self.deceleration, min(self.min_speed, start))


class BrigadeLayer(Layer):
    """The intermediate layer of §5.4: parameters and helpers for every Fire Brigade layer."""

    default_request_timeout = math.inf
    """Requests here go to the robotic layer, which answers when a physical action is
    over (a long drive, a hand-over): however long it takes."""

    def __init__(self, params: Params) -> None:
        self.params = params

    @property
    def kind(self) -> Kind:
        """This robot's kind."""
        return self.params.kind

    def in_world(self, *points: Point) -> bool:
        """Whether every point is inside the world (up to rounding).

        What another robot says is checked before it is acted upon: a message's
        bounds make its numbers finite, this makes its positions possible.
        """
        width, height = self.params.world
        slack = 1e-6
        return all(
            -slack <= x <= width + slack and -slack <= y <= height + slack for x, y in points
        )

    def unexpected(self, msg: Message, why: str) -> None:
        """Logs a message this layer's state machine has no use for (never raised)."""
        self.log.warning("ignored %r: %s", msg, why)

    def late(self, msg: Message, why: str) -> None:
        """Logs a message that came too late or twice: routine on a lossy network."""
        self.log.debug("ignored %r: %s", msg, why)
