"""The Fire Brigade's messages (thesis §5.6, Table III), declared as typed classes.

The thesis's messages carry a communication type (negotiation, accept, deny);
here that is the header's ``msg_type``, set by the runtime for requests and
replies. Which layer uses which message:

* ``RequestInfo``: Goal to every robot's Goal (NEGOTIATION: "where are you, what
  are you?"), answered with the replier's position and kind; also how a layer asks
  its own Action layer where the robot is.
* ``ChangeStatus``: status changes between neighbouring layers, down (new
  responsibilities: "MoveBucket", "Partnered", "Meeting", "Carry", "Rotate",
  "Move", "SwapBucket", "MakeBucket") and up (their completion: "Exchanged",
  "Moved"). One class with optional fields, as in the thesis.
* ``RequestRobotsInRange``: Strategy to Action (NEGOTIATION); the reply lists the
  robots within range and the asker's own position and speed.
* ``RequestPartner``: Strategy to Strategy: a partnership request (NEGOTIATION)
  and its ACCEPT or DENY.
* ``Meet``: Group Activity to Group Activity: the giver's position and fatigue
  (NEGOTIATION); the partner answers with the meeting point (ACCEPT) or DENY.
* ``Meeting``: Task to Task: "I am at the meeting point" (NEGOTIATION), answered
  (ACCEPT) once the partner is there too.
* ``Handover``: Task to Task: the giver's notice that the bucket changed hands.
* ``CompletionStatus``: Action to Task: an action finished, and where the robot is.
"""

from __future__ import annotations

import enum
from typing import Annotated, TypeAlias

from cas_async import Bounds, Finite, Message, message

__all__ = [
    "MESSAGES",
    "ChangeStatus",
    "CompletionStatus",
    "Coordinate",
    "Distance",
    "Handover",
    "Kind",
    "Meet",
    "Meeting",
    "RequestInfo",
    "RequestPartner",
    "RequestRobotsInRange",
    "Speed",
]


Coordinate: TypeAlias = Annotated[float, Finite]
"""A position's x or y: finite, checked when a message arrives (NaN never reaches a layer)."""

Speed: TypeAlias = Annotated[float, Finite, Bounds(ge=0)]
"""A speed: finite and not negative."""

Distance: TypeAlias = Annotated[float, Finite, Bounds(ge=0)]
"""A radius: finite and not negative."""


class Kind(enum.IntEnum):
    """The three kinds of robot of the Fire Brigade (§5.1)."""

    GENERATOR = 0
    SINK = 1
    TRANSPORTER = 2


@message
class RequestInfo(Message):
    """Position and kind of a robot (and its current speed, 0 when immobile)."""

    x: Coordinate = 0.0
    y: Coordinate = 0.0
    kind: Kind = Kind.TRANSPORTER
    speed: Speed = 0.0


@message
class ChangeStatus(Message):
    """A new responsibility (downwards) or its completion (upwards); see the module docs.

    ``x, y`` is the point the status is about (a meeting point, a leg's end, the
    robot's position); ``sink`` and ``sink_x, sink_y`` the bucket's destination;
    ``deal`` identifies a partnership (see ``RequestPartner``).
    """

    status: str
    partner: int = -1
    x: Coordinate = 0.0
    y: Coordinate = 0.0
    has_bucket: bool = False
    bucket: int = -1
    sink: int = -1
    sink_x: Coordinate = 0.0
    sink_y: Coordinate = 0.0
    deal: int = -1


@message
class RequestRobotsInRange(Message):
    """The robots within ``radius`` (reply: ids and positions, nearest first).

    The reply also carries the asking robot's own position and current speed, which
    the Strategy needs to estimate meeting times.
    """

    radius: Distance
    ids: list[int] | None = None
    xs: list[Coordinate] | None = None
    ys: list[Coordinate] | None = None
    x: Coordinate = 0.0
    y: Coordinate = 0.0
    speed: Speed = 0.0


@message
class RequestPartner(Message):
    """A partnership request (NEGOTIATION) from a robot holding ``bucket``, or its answer.

    The request carries the asker's position, kind and the bucket's destination; the
    answer (ACCEPT or DENY) carries the replier's position and kind. An accepted
    request's ``msg_id`` becomes the partnership's ``deal``: the later messages of
    the partnership carry it, so a late message of an earlier partnership between
    the same two robots is never taken for one of this partnership.
    """

    x: Coordinate
    y: Coordinate
    kind: Kind
    bucket: int = -1
    sink: int = -1
    sink_x: Coordinate = 0.0
    sink_y: Coordinate = 0.0


@message
class Meet(Message):
    """Coordinating the meeting point.

    The giver sends its position, kind and fatigue (``speed`` now; 0 when immobile)
    as a NEGOTIATION; the partner answers ACCEPT with the meeting point in ``x, y``,
    or DENY when it is not partnered with the giver.
    """

    x: Coordinate
    y: Coordinate
    kind: Kind = Kind.TRANSPORTER
    speed: Speed = 0.0
    deal: int = -1


@message
class Meeting(Message):
    """Waiting for the partner at the meeting point (NEGOTIATION), and "here too" (ACCEPT)."""

    deal: int


@message
class Handover(Message):
    """Sent by the giver once ``bucket`` is in the partner's hands."""

    bucket: int
    deal: int


@message
class CompletionStatus(Message):
    """The Action layer's report: what finished, and the robot's pose and bucket now."""

    action: str
    x: Coordinate = 0.0
    y: Coordinate = 0.0
    heading: Coordinate = 0.0
    has_bucket: bool = False
    bucket: int = -1


MESSAGES: tuple[type[Message], ...] = (
    RequestInfo,
    ChangeStatus,
    RequestRobotsInRange,
    RequestPartner,
    Meet,
    Meeting,
    Handover,
    CompletionStatus,
)
"""Every message of the Fire Brigade's stack: they make up its fingerprint."""
