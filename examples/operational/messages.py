"""The rendezvous application's messages: one typed class per meaning.

Between robots (the Gather layers of two robots, external):

* ``Hello``: "I have just arrived: introduce yourselves"; broadcast once, at start,
  to the robots already there.
* ``Introduce`` / ``Home``: a request with the asker's home, answered with the
  replier's: one round trip and both robots know where the other one started.
* ``Arrived``: "I am at the rendezvous (x, y)"; told to every robot known, each
  time this robot reaches the point it agreed to.

Inside a robot (Gather and Drive, internal):

* ``Locate`` / ``Located``: where is the robot now? (a request, answered at once).
* ``DriveTo``: go to (x, y); one-way, the robotic layer drives one leg at a time.
* ``Reached``: sent up when a leg is over, with the position reached; legs are
  numbered, so an old leg's end is never taken for the latest one's.

Wire names are the contract between processes: a robot in another process decodes
by them, and they must be unique in every process that imports these classes, so
they carry the application's prefix. Coordinates are finite (checked on arrival:
a NaN never reaches a layer).
"""

from __future__ import annotations

from typing import Annotated, TypeAlias

from cas_async import Finite, Message

__all__ = [
    "MESSAGES",
    "Arrived",
    "Coordinate",
    "DriveTo",
    "Hello",
    "Home",
    "Introduce",
    "Locate",
    "Located",
    "Reached",
]

Coordinate: TypeAlias = Annotated[float, Finite]
"""A position's x or y, in metres."""


# -- between robots -----------------------------------------------------------------------


class Hello(Message):
    """A robot has just started: the robots that receive it introduce themselves."""


class Introduce(Message):
    """The asker's home (NEGOTIATION), answered with the replier's :class:`Home`."""

    x: Coordinate
    y: Coordinate


class Home(Message):
    """The answer to :class:`Introduce`: where the replier started."""

    x: Coordinate
    y: Coordinate


class Arrived(Message):
    """The sender is at the rendezvous ``(x, y)`` (the point it agreed to)."""

    x: Coordinate
    y: Coordinate


# -- inside a robot -----------------------------------------------------------------------


class Locate(Message):
    """Where is the robot? (NEGOTIATION to the robotic layer), answered with :class:`Located`."""


class Located(Message):
    """The robot's position and heading now."""

    x: Coordinate
    y: Coordinate
    heading: Annotated[float, Finite]


class DriveTo(Message):
    """Drive to ``(x, y)``: leg number ``leg``, after the legs asked for before it."""

    x: Coordinate
    y: Coordinate
    leg: int


class Reached(Message):
    """Leg number ``leg`` is over: the robot stands at ``(x, y)``."""

    x: Coordinate
    y: Coordinate
    leg: int


MESSAGES: tuple[type[Message], ...] = (
    Hello,
    Introduce,
    Home,
    Arrived,
    Locate,
    Located,
    DriveTo,
    Reached,
)
"""Every message of the stack: pass it as ``Robot(..., messages=MESSAGES)`` in every process,
so the stack fingerprints are equal whatever else a process imports."""
