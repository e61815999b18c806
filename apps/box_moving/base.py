"""What every box-moving layer shares: the levels, the robot's constants, the termination.

:class:`Shared` is the intermediate class between the framework's ``Layer``
and the four layers (as the thesis's §5.4 adds one for the Fire Brigade): the
robot's :class:`Params`, the number of objects moved that the layer has
learnt, and the termination condition, the same in every layer (thesis §4.4):
``target`` objects moved. :class:`BoxLayer` is the base of the three upper
layers, which are built alike (``cls(params)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from cas_async import Layer, Message

__all__ = ["ACTION", "COORDINATION", "DECISION_MAKING", "TASK", "BoxLayer", "Params", "Shared"]

DECISION_MAKING: Final = 0
TASK: Final = 1
COORDINATION: Final = 2
ACTION: Final = 3
"""Levels of the four layers, top (0) to bottom (3), as in the thesis's Fig. 19."""


@dataclass(frozen=True, slots=True)
class Params:
    """One robot's constants, the same in all of its layers.

    Attributes:
        target: objects to be moved for the mission to be over (thesis: five).
        peers: every other robot, by id.
        speed: the robot's speed without a load, distance units per second.
        payload: the weight it lifts alone.
        slowdown: the fraction of its speed a robot loses at full payload; a
            load of ``w`` slows it to ``speed * (1 - slowdown * w / payload)``.
        lift_time: seconds a lift takes.
        put_down_time: seconds a put-down takes.
        leg_length: the longest leg of a joint carry.
        sync_margin: seconds between the leader's decision to start a leg and
            the start, so that the helper hears of it in time.
        retry_interval: seconds before asking for a partner again, or looking
            for objects again, after nobody could.
        timeout: seconds to wait for another robot's answer before asking again.
        retries: times a question is asked again before giving up.
    """

    target: int
    peers: tuple[int, ...]
    speed: float
    payload: float
    slowdown: float = 0.5
    lift_time: float = 1.0
    put_down_time: float = 1.0
    leg_length: float = 2.0
    sync_margin: float = 0.2
    retry_interval: float = 2.0
    timeout: float = 0.5
    retries: int = 6

    def lifts_alone(self, weight: float) -> bool:
        """Whether this robot can carry an object of ``weight`` by itself."""
        return weight <= self.payload

    def carrying_speed(self, weight: float, partner_payload: float = 0.0) -> float:
        """This robot's speed carrying ``weight``, alone or with a partner of ``partner_payload``.

        A pair shares the weight in proportion to the payloads, so each carries
        the same fraction of what it can lift: ``weight / (payload + partner_payload)``.
        """
        load = min(1.0, weight / (self.payload + partner_payload))
        return self.speed * (1.0 - self.slowdown * load)


class Shared(Layer):
    """What all four layers share: the parameters, and the objects the layer knows are moved."""

    default_request_timeout = math.inf
    """Requests to the Action layer are answered when it is free: however long that takes."""

    def __init__(self, params: Params) -> None:
        self.params = params
        self.moved = 0  # objects this layer knows lie in the drop zone

    def termination_condition(self) -> bool:
        """``target`` objects are known to be moved: the same condition in every layer."""
        return self.moved >= self.params.target

    def learn_moved(self, moved: int) -> bool:
        """Takes a count of moved objects; whether it was news."""
        if moved <= self.moved:
            return False
        self.moved = moved
        return True

    def unexpected(self, msg: Message, why: str) -> None:
        """Logs a message this layer's state machine has no use for (never raised)."""
        self.log.warning("ignored %r: %s", msg, why)

    def late(self, msg: Message, why: str) -> None:
        """Logs a message overtaken by events: routine when robots act at once."""
        self.log.debug("ignored %r: %s", msg, why)


class BoxLayer(Shared):
    """The base of the three upper layers, each built as ``cls(params)``.

    A scenario's ``[layers]`` may put a subclass of it in place of Decision-Making,
    Task or Coordination. The Action layer shares :class:`Shared` but is built
    with the robot's middleware and gripper too, so it is not one of these.
    """
