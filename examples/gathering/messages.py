"""The gathering's messages: one typed class per meaning.

Between robots (the Plan layers, external):

* ``Position``: "I am at (x, y)"; each robot broadcasts its own once, at start.

Inside a robot (Plan asks, Drive answers; internal):

* ``DriveTo`` / ``Arrived``: drive to (x, y); the answer says where the robot stopped.

Each class is a message by deriving from ``Message``: its fields are positional
(``Position(1.0, 2.0)``), its header is filled by the runtime. A robot decodes
only the messages of its own stack, so another app's ``DriveTo`` never clashes.
"""

from __future__ import annotations

from typing import Annotated, TypeAlias

from cas_async import Finite, Message

__all__ = ["MESSAGES", "Arrived", "Coordinate", "DriveTo", "Position"]

Coordinate: TypeAlias = Annotated[float, Finite]
"""A position's x or y, in metres (checked on arrival: a NaN never reaches a layer)."""


class Position(Message):
    """Where the sender stands."""

    x: Coordinate
    y: Coordinate


class DriveTo(Message):
    """Drive to ``(x, y)``: a request to the robotic layer, answered with :class:`Arrived`."""

    x: Coordinate
    y: Coordinate


class Arrived(Message):
    """The drive is over: the robot stands at ``(x, y)``."""

    x: Coordinate
    y: Coordinate


MESSAGES: tuple[type[Message], ...] = (Position, DriveTo, Arrived)
"""Every message of the stack: give it to every robot (``Robot(..., messages=MESSAGES)``)."""
