"""The Fire Brigade's messages (thesis §5.6, Table III): one typed class per meaning.

Each class carries only the fields its meaning needs, and a layer dispatches on
the class (``match msg: case MoveBucket(): ...``). The thesis's communication type
(negotiation, accept, deny) is the header's ``msg_type``, set by the runtime for
requests and replies. A question and its answer are two classes when they carry
different things (``RequestInfo`` is answered by ``RobotInfo``).

Between robots (external; the same layer of two robots):

* ``RequestInfo`` / ``RobotInfo``: Goal to Goal, "where are you, what are you?"
  (NEGOTIATION), answered with the replier's position, kind and speed.
* ``RequestPartner`` / ``PartnerAnswer``: Strategy to Strategy, a partnership
  request for a bucket and its destination (NEGOTIATION), answered ACCEPT or DENY
  with the replier's kind.
* ``Meet`` / ``MeetingPoint``: Group Activity to Group Activity, the giver's position,
  kind and speed (NEGOTIATION), answered with the meeting point (ACCEPT) or DENY.
* ``Meeting``: Task to Task, "I am at the meeting point" (NEGOTIATION), answered
  (ACCEPT) once the partner is there too.
* ``Handover``: Task to Task, the giver's notice that the bucket changed hands.

Between the layers of one robot (internal), downwards, new responsibilities:

* ``MoveBucket``: Goal to Strategy, a bucket to get to a sink.
* ``Partnered``: Strategy to Group Activity, a partnership agreed (giver or receiver).
* ``Carry``: Strategy to Task (through Group Activity), a leg carried alone.
* ``MeetAt``: Group Activity to Task, the meeting point of a partnership.

and upwards, their completion:

* ``Exchanged``: Task to Goal (through Group Activity and Strategy): the bucket
  changed hands.
* ``Moved``: Task to Strategy (through Group Activity): a ``Carry`` leg is done.
* ``Abandoned``: Task or Group Activity to Strategy: a partnership given up.

The Action layer's requests (NEGOTIATION, answered when the action is over):

* ``RequestInfo``: from Goal and Group Activity, answered with ``RobotInfo``.
* ``RequestRobotsInRange``: from Goal and Strategy, answered with ``RobotsInRange``.
* ``MakeBucket``: from Goal, answered with ``BucketMade``.
* The Task layer's commands (:data:`Command`): ``Where``, ``Rotate``, ``Move``,
  ``HoldOut``, ``Withdraw``, ``Give``, ``Take``, each answered with
  ``CompletionStatus``: the robot's pose, and whether it holds the bucket.

A bucket's destination, a Sink's id and position, travels as one nested
:class:`Destination` in every message that needs it (``to``).
"""

from __future__ import annotations

import enum
from typing import Annotated, TypeAlias

import msgspec

from cas_async import Finite, Message, finite

__all__ = [
    "MESSAGES",
    "Abandoned",
    "BucketMade",
    "Carry",
    "Command",
    "CompletionStatus",
    "Coordinate",
    "Destination",
    "Distance",
    "Exchanged",
    "Give",
    "Handover",
    "HoldOut",
    "Kind",
    "MakeBucket",
    "Meet",
    "MeetAt",
    "Meeting",
    "MeetingPoint",
    "Move",
    "MoveBucket",
    "Moved",
    "PartnerAnswer",
    "Partnered",
    "RequestInfo",
    "RequestPartner",
    "RequestRobotsInRange",
    "RobotInfo",
    "RobotsInRange",
    "Rotate",
    "Speed",
    "Take",
    "Where",
    "Withdraw",
]


Coordinate: TypeAlias = Annotated[float, Finite]
"""A position's x or y: finite, checked when a message arrives (NaN never reaches a layer)."""

Speed: TypeAlias = Annotated[float, finite(ge=0)]
"""A speed: finite and not negative."""

Distance: TypeAlias = Annotated[float, finite(ge=0)]
"""A radius: finite and not negative."""


class Destination(msgspec.Struct, frozen=True, array_like=True):
    """Where a bucket goes: the Sink ``sink``, standing at ``x, y``.

    It travels with the bucket, nested in the messages about it.
    """

    sink: int
    x: Coordinate
    y: Coordinate

    @property
    def at(self) -> tuple[float, float]:
        """The Sink's position."""
        return (self.x, self.y)


class Kind(enum.IntEnum):
    """The three kinds of robot of the Fire Brigade (§5.1)."""

    GENERATOR = 0
    SINK = 1
    TRANSPORTER = 2


# -- between robots ---------------------------------------------------------------------------


class RequestInfo(Message):
    """Where is a robot, and what is it? Answered with :class:`RobotInfo`.

    Sent to other robots' Goal layers, and by a layer to its own Action layer.
    """


class RobotInfo(Message):
    """A robot's position, kind and current speed (0 when immobile)."""

    x: Coordinate
    y: Coordinate
    kind: Kind
    speed: Speed


class RequestPartner(Message):
    """Will you take ``bucket`` (NEGOTIATION)? Answered with :class:`PartnerAnswer`.

    The asker's position and kind, and the bucket's destination. An accepted
    request's ``msg_id`` becomes the partnership's ``deal``: the later messages
    of the partnership carry it, so a late message of an earlier partnership
    between the same two robots is never taken for one of this partnership.
    """

    x: Coordinate
    y: Coordinate
    kind: Kind
    bucket: int
    to: Destination


class PartnerAnswer(Message):
    """The answer to a :class:`RequestPartner`: ACCEPT or DENY, and the replier's kind."""

    kind: Kind


class Meet(Message):
    """The giver's position, kind and speed now (0 when immobile), to agree where to meet.

    Sent as a NEGOTIATION, answered with :class:`MeetingPoint`.
    """

    x: Coordinate
    y: Coordinate
    kind: Kind
    speed: Speed
    deal: int


class MeetingPoint(Message):
    """The answer to :class:`Meet`: ACCEPT with where to meet, or DENY.

    A partner refuses (DENY) a ``Meet`` of a partnership it does not (or no longer)
    have; ``x, y`` then repeat the giver's own position: there is nowhere to go.
    """

    x: Coordinate
    y: Coordinate
    deal: int


class Meeting(Message):
    """Waiting for the partner at the meeting point (NEGOTIATION), and "here too" (ACCEPT)."""

    deal: int


class Handover(Message):
    """Sent by the giver once ``bucket`` is in the partner's hands."""

    bucket: int
    deal: int


# -- down the stack: responsibilities ---------------------------------------------------------


class MoveBucket(Message):
    """Goal to Strategy: get ``bucket`` to its destination ``to``."""

    bucket: int
    to: Destination


class Partnered(Message):
    """Strategy to Group Activity: a partnership with ``partner`` over ``bucket``.

    ``giver`` tells which side this robot is on; the destination travels with the
    bucket; ``deal`` identifies the partnership (see :class:`RequestPartner`).
    """

    partner: int
    giver: bool
    bucket: int
    to: Destination
    deal: int


class Carry(Message):
    """Strategy to Task (through Group Activity): carry the bucket alone to ``x, y``."""

    x: Coordinate
    y: Coordinate


class MeetAt(Message):
    """Group Activity to Task: meet ``partner`` at ``x, y`` and swap the bucket there.

    The rest is the partnership's (see :class:`Partnered`).
    """

    partner: int
    x: Coordinate
    y: Coordinate
    giver: bool
    bucket: int
    to: Destination
    deal: int


# -- up the stack: completions ----------------------------------------------------------------


class Exchanged(Message):
    """Task to Goal: ``bucket`` changed hands with ``partner``; this robot is at ``x, y``.

    ``has_bucket``: whether this robot holds the bucket now (a receiver, unless it
    is a Sink, which disposes of what it receives). The destination is the
    bucket's: a receiver takes it over.
    """

    partner: int
    bucket: int
    has_bucket: bool
    x: Coordinate
    y: Coordinate
    to: Destination


class Moved(Message):
    """Task to Strategy: a :class:`Carry` leg is done; the robot is at ``x, y``."""

    x: Coordinate
    y: Coordinate


class Abandoned(Message):
    """Task or Group Activity to Strategy: the partnership with ``partner`` was given up.

    ``has_bucket``: whether this robot holds the bucket (a giver does: it looks for
    another partner).
    """

    partner: int
    has_bucket: bool


# -- to the Action layer ----------------------------------------------------------------------


class RequestRobotsInRange(Message):
    """Which robots are within ``radius``? Answered with :class:`RobotsInRange`."""

    radius: Distance


class RobotsInRange(Message):
    """The robots within range, nearest first (``ids`` at ``xs, ys``).

    Also the asking robot's own position and current speed, which the Strategy
    needs to estimate meeting times.
    """

    ids: list[int]
    xs: list[Coordinate]
    ys: list[Coordinate]
    x: Coordinate
    y: Coordinate
    speed: Speed


class MakeBucket(Message):
    """Make a new bucket in the robot's hands (a Generator). Answered with :class:`BucketMade`."""


class BucketMade(Message):
    """The bucket made, and where the robot is."""

    bucket: int
    x: Coordinate
    y: Coordinate


class Where(Message):
    """No action: report the pose, and whether the robot holds a bucket."""


class Rotate(Message):
    """Turn to face ``x, y``."""

    x: Coordinate
    y: Coordinate


class Move(Message):
    """Drive to ``x, y``."""

    x: Coordinate
    y: Coordinate


class HoldOut(Message):
    """Hold the hands out to ``partner``: a hand-over from it may succeed (the thesis's Accept)."""

    partner: int


class Withdraw(Message):
    """Withdraw the hands from ``partner``; report whether ``bucket`` is in them."""

    partner: int
    bucket: int


class Give(Message):
    """Hand ``bucket`` over to ``partner`` (it fails into hands not held out)."""

    bucket: int
    partner: int


class Take(Message):
    """Take ``bucket``, which ``partner`` reported handing over (a Sink disposes of it)."""

    bucket: int
    partner: int


class CompletionStatus(Message):
    """The Action layer's report of a :data:`Command`: the robot's pose now.

    ``has_bucket``: whether the command's bucket is held now (``Withdraw``,
    ``Give``, ``Take``); for the other commands, whether any bucket is held.
    """

    x: Coordinate
    y: Coordinate
    heading: Coordinate
    has_bucket: bool


Command: TypeAlias = Where | Rotate | Move | HoldOut | Withdraw | Give | Take
"""The Task layer's commands to the Action layer, each answered with a CompletionStatus."""


MESSAGES: tuple[type[Message], ...] = (
    # between robots
    RequestInfo,
    RobotInfo,
    RequestPartner,
    PartnerAnswer,
    Meet,
    MeetingPoint,
    Meeting,
    Handover,
    # down the stack
    MoveBucket,
    Partnered,
    Carry,
    MeetAt,
    # up the stack
    Exchanged,
    Moved,
    Abandoned,
    # to the Action layer, and its answers
    RequestRobotsInRange,
    RobotsInRange,
    MakeBucket,
    BucketMade,
    Where,
    Rotate,
    Move,
    HoldOut,
    Withdraw,
    Give,
    Take,
    CompletionStatus,
)
"""Every message of the Fire Brigade's stack, each once: they make up its fingerprint."""
