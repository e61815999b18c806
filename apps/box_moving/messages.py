"""The box-moving messages (thesis §4.4): one typed class per meaning.

A layer dispatches on the class (``match msg: case SelectedObject(): ...``); the
thesis's communication type (negotiation, accept, deny) is the header's
``msg_type``. A robot decodes only its own stack's messages, so the Fire
Brigade's classes of the same name (``RequestPartner``) never clash with these,
even in one process.

An object, as a robot's sensors see it, travels as a nested :class:`Sighting`:
its id, where it is, its weight and size, and its drop spot.

Between robots (external; the same layer of two robots):

* ``SelectedObject`` / ``SelectionAnswer``: Decision-Making to Decision-Making,
  "I selected this object" (NEGOTIATION), answered ACCEPT (no conflict) or DENY.
* ``RequestPartner`` / ``PartnerAnswer``: Task to Task, "help me carry this
  object" (NEGOTIATION), answered ACCEPT or DENY, saying whether the two could
  lift it at all.
* ``Dismiss``: Task to Task, "I no longer need your help" (NEGOTIATION, the
  answer is a ``Dismiss`` too).
* ``OfferHelp``: Task to Task, "I refused you while busy; I am free now: shall
  I help?" (NEGOTIATION, answered ACCEPT or DENY with an ``OfferHelp``).
* ``Balance`` / ``Balanced``: Coordination to Coordination, the leader's
  position and carrying speed (NEGOTIATION), answered with the sides each robot
  lifts and the common speed (AgreeOnBalancing).
* ``Ready``, ``Go``, ``Release``: Coordination to Coordination during a joint
  carry: the helper is ready for a leg; the leader's start of a leg, or of the
  put-down, at an agreed instant.

Between the layers of one robot (internal), downwards:

* ``Scan``: Decision-Making to Action, answered (later, upwards) by ``ScanResult``.
* ``Claim`` / ``Unclaim``: Decision-Making to Action, mark the selected object
  as this robot's (the Floor records the instant: the selection time), or unmark it.
* ``ChangeStatus``: Decision-Making to Task, the object this robot is to move (InformTask).
* ``Assignment``: Task to Coordination, a carry alone, as leader or as helper
  (InformCoordination); ``Dismissed``: the helper's carry is off.
* ``CarryOut``: Coordination to Action, the carry as agreed (InformAction; see
  the README on why this is not a second ``ChangeStatus``).
* ``Ready`` (upwards), ``Go``, ``Release``: the joint carry's steps.

and upwards, completions:

* ``CarryDone``: Action to Decision-Making, hop by hop: the carry of an object is over.
* ``MovedCount``: Action to Decision-Making, hop by hop: objects in the drop zone.
* ``Helping``, ``Released``, ``GiveUp``: Task to Decision-Making: this robot
  helps another; it no longer does; nobody can help with the selected object.

Requests answered at once by the Action layer: ``Where`` (``Position``) and
``Locate`` (``Located``: the other robots' positions).
"""

from __future__ import annotations

import enum
from typing import Annotated, TypeAlias

import msgspec

from cas_async import Finite, Message, finite

__all__ = [
    "MESSAGES",
    "Assignment",
    "Balance",
    "Balanced",
    "CarryDone",
    "CarryOut",
    "ChangeStatus",
    "Claim",
    "Coordinate",
    "Dismiss",
    "Dismissed",
    "GiveUp",
    "Go",
    "Helping",
    "Locate",
    "Located",
    "MovedCount",
    "OfferHelp",
    "PartnerAnswer",
    "Position",
    "Ready",
    "Release",
    "Released",
    "RequestPartner",
    "Role",
    "Scan",
    "ScanResult",
    "SelectedObject",
    "SelectionAnswer",
    "Side",
    "Sighting",
    "Unclaim",
    "Where",
]

Coordinate: TypeAlias = Annotated[float, Finite]
"""A position's x or y, or an instant: finite, checked when a message arrives."""

Amount: TypeAlias = Annotated[float, finite(ge=0)]
"""A weight, size or speed: finite and not negative.

(Not "above zero": the senders never send zero, but a zero would be a
well-formed value for a layer to refuse, not a malformed message.)"""


class Side(enum.IntEnum):
    """The side of an object a robot lifts it from (west is toward -x, south toward -y)."""

    WEST = 0
    EAST = 1
    SOUTH = 2
    NORTH = 3

    @property
    def opposite(self) -> Side:
        """The side across the object."""
        return _OPPOSITE[self]


_OPPOSITE = {
    Side.WEST: Side.EAST,
    Side.EAST: Side.WEST,
    Side.SOUTH: Side.NORTH,
    Side.NORTH: Side.SOUTH,
}


class Role(enum.IntEnum):
    """What a robot does in a carry."""

    SOLO = 0
    """It carries the object alone."""
    LEADER = 1
    """It selected the object and asked for help: it paces the joint carry."""
    HELPER = 2
    """It helps the leader."""


class Sighting(msgspec.Struct, frozen=True, array_like=True):
    """An object as a robot's sensors see it: where, how heavy, how big, and where it goes.

    Attributes:
        obj: the object's id.
        x, y: its centre.
        weight: what it weighs (payload units).
        size: the side of its square footprint.
        drop_x, drop_y: its drop spot, inside the destination zone.
    """

    obj: int
    x: Coordinate
    y: Coordinate
    weight: Amount
    size: Amount
    drop_x: Coordinate
    drop_y: Coordinate


# -- between robots ---------------------------------------------------------------------------


class SelectedObject(Message):
    """Decision-Making to Decision-Making: this robot selected ``obj`` (NEGOTIATION)."""

    obj: int


class SelectionAnswer(Message):
    """The answer to :class:`SelectedObject`: ACCEPT (no conflict) or DENY."""

    obj: int


class RequestPartner(Message):
    """Task to Task: help carry ``object`` (NEGOTIATION); ``payload`` is the asker's."""

    object: Sighting
    payload: Amount


class PartnerAnswer(Message):
    """The answer to :class:`RequestPartner`: ACCEPT or DENY.

    Attributes:
        obj: the object asked about.
        able: whether the two robots' payloads together lift it (a DENY from a
            robot too weak to help says ``False``).
        payload: the replier's payload.
    """

    obj: int
    able: bool
    payload: Amount


class Dismiss(Message):
    """Task to Task: the leader no longer needs this robot's help with ``obj`` (NEGOTIATION)."""

    obj: int


class OfferHelp(Message):
    """Task to Task: "I am free now: shall I help you with ``obj``?" (NEGOTIATION).

    Sent by a robot that refused an earlier :class:`RequestPartner` because it
    was busy, once it is free; answered with an ``OfferHelp`` too, ACCEPT (the
    asker still waits: the two carry it) or DENY. ``payload`` is the offerer's.
    """

    obj: int
    payload: Amount


class Balance(Message):
    """Coordination to Coordination: the leader's position and carrying speed (NEGOTIATION)."""

    obj: int
    x: Coordinate
    y: Coordinate
    speed: Amount


class Balanced(Message):
    """The answer to :class:`Balance`: the sides each robot lifts, and the common speed."""

    obj: int
    leader_side: Side
    helper_side: Side
    speed: Amount


class Ready(Message):
    """This robot holds ``obj`` at the start of leg ``leg`` (after the last: the put-down)."""

    obj: int
    leg: int


class Go(Message):
    """Start leg ``leg`` at instant ``at``: the object's centre goes to ``x, y``."""

    obj: int
    leg: int
    x: Coordinate
    y: Coordinate
    at: Coordinate


class Release(Message):
    """Put ``obj`` down, starting at instant ``at``: the joint carry's last step."""

    obj: int
    at: Coordinate


# -- down the stack ---------------------------------------------------------------------------


class Scan(Message):
    """Decision-Making to Action: look for objects; answered upwards by :class:`ScanResult`."""


class ScanResult(Message):
    """Action to Decision-Making: the robot's position, the free objects, how many are moved."""

    x: Coordinate
    y: Coordinate
    objects: list[Sighting]
    moved: int


class Claim(Message):
    """Decision-Making to Action: mark ``obj`` as this robot's (it selected it)."""

    obj: int


class Unclaim(Message):
    """Decision-Making to Action: take this robot's mark off ``obj`` (it let the selection go)."""

    obj: int


class ChangeStatus(Message):
    """Decision-Making to Task (InformTask): ``object`` is the one this robot moves now."""

    object: Sighting


class Assignment(Message):
    """Task to Coordination (InformCoordination): carry ``object`` in ``role``.

    ``partner`` and ``partner_payload`` are the other robot's (0 when alone).
    """

    object: Sighting
    role: Role
    partner: int = 0
    partner_payload: float = 0.0


class Dismissed(Message):
    """Task to Coordination: the help with ``obj`` is off (the leader found another way)."""

    obj: int


class CarryOut(Message):
    """Coordination to Action (InformAction): the carry of ``object`` as agreed.

    Attributes:
        object: the object.
        role: alone, leader or helper.
        side: the side this robot lifts.
        speed: the carrying speed (the pair's common speed in a joint carry).
        partner: the other robot of a joint carry (0 when alone).
    """

    object: Sighting
    role: Role
    side: Side
    speed: Amount
    partner: int = 0


# -- up the stack -----------------------------------------------------------------------------


class CarryDone(Message):
    """Action to Decision-Making, hop by hop: this robot's carry of ``obj`` is over."""

    obj: int


class MovedCount(Message):
    """Action to Decision-Making, hop by hop: ``moved`` objects lie in the drop zone."""

    moved: int


class Helping(Message):
    """Task to Decision-Making: this robot helps ``leader`` with ``obj``: drop any selection."""

    obj: int
    leader: int


class Released(Message):
    """Task to Decision-Making: the help with ``obj`` is off: this robot is free again."""

    obj: int


class GiveUp(Message):
    """Task to Decision-Making: no robot can help lift ``obj``: select another one."""

    obj: int


# -- the Action layer's queries ---------------------------------------------------------------


class Where(Message):
    """Where is this robot? Answered with :class:`Position`."""


class Position(Message):
    """The robot's position and heading."""

    x: Coordinate
    y: Coordinate
    heading: Coordinate


class Locate(Message):
    """Where are the other robots? Answered with :class:`Located`."""


class Located(Message):
    """The other robots, nearest first, and this robot's position."""

    ids: list[int]
    xs: list[float]
    ys: list[float]
    x: Coordinate
    y: Coordinate


MESSAGES: tuple[type[Message], ...] = (
    # between robots
    SelectedObject,
    SelectionAnswer,
    RequestPartner,
    PartnerAnswer,
    Dismiss,
    OfferHelp,
    Balance,
    Balanced,
    Ready,
    Go,
    Release,
    # down the stack
    Scan,
    ScanResult,
    Claim,
    Unclaim,
    ChangeStatus,
    Assignment,
    Dismissed,
    CarryOut,
    # up the stack
    CarryDone,
    MovedCount,
    Helping,
    Released,
    GiveUp,
    # queries
    Where,
    Position,
    Locate,
    Located,
)
"""Every message of the box-moving stack, each once: they make up its fingerprint."""
