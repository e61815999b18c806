"""The Decision-Making layer (thesis §4.4, Fig. 21: SelectObject, InformTask).

Its state machine follows Fig. 21. The layer is suspended until an event
activates it (the robot's start, a message, a timer); it then checks whether an
object is selected. If not, it enters *Selecting Object*: it sends a ``Scan``
request down to the Action layer and suspends. On the scan's result it selects
an object (by default the nearest, ties by id: :meth:`DecisionMaking.choose`),
and agrees with every other robot that there is no conflict: it sends
``SelectedObject`` to each (NEGOTIATION), and each answers ACCEPT or DENY. On
a DENY it tries the next object of the same scan; when none is left, it waits
``retry_interval`` and scans again. Once all accepted, it marks the object as
its own (``Claim``, to the Action layer: the Floor records the instant) and
informs the Task layer (InformTask: ``ChangeStatus``, a request the Task layer
answers at once: ACCEPT, or DENY when it has just agreed to help another robot,
and the selection is released).

A conflict, in answering another robot's ``SelectedObject`` (on arrival, even
while this layer waits for answers of its own): this robot already selected
that object, or helps carry it (DENY); or it is selecting the same object at
this very moment, and then the lower id wins: the higher id accepts and gives
its own candidate up.

The Task layer may tell it that this robot helps another (``Helping``): the
selection is released (``Unclaim``). After a carry (``CarryDone``), the end of
a help (``Released``), or a selection nobody can lift (``GiveUp``: never
selected again), the layer selects again. It stops selecting once ``target``
objects are moved (the termination condition, learnt from the scans and from
``MovedCount``).
"""

from __future__ import annotations

import enum
from collections.abc import Hashable, Sequence

from cas_async import Message, MsgType, RequestTimeout

from .base import ACTION, BoxLayer, Params
from .geometry import Point, distance
from .messages import (
    CarryDone,
    ChangeStatus,
    Claim,
    GiveUp,
    Helping,
    MovedCount,
    Released,
    Scan,
    ScanResult,
    SelectedObject,
    SelectionAnswer,
    Sighting,
    Unclaim,
)

__all__ = ["DecisionMaking", "State"]

_RESCAN = "rescan"
"""The timer of a new scan after a round in which no object could be selected."""


class State(enum.Enum):
    """The states of Fig. 21 (and what the figure leaves implicit)."""

    SUSPENDED = "suspended"
    """No object selected, nothing under way: the next activation selects."""
    SELECTING = "selecting"
    """Selecting Object: a scan was requested; its result is awaited."""
    BACKING_OFF = "backing off"
    """No object could be selected: waiting ``retry_interval`` before scanning again."""
    SELECTED = "selected"
    """An object is selected and the Task layer informed."""
    HELPING = "helping"
    """This robot helps another robot carry its object."""
    DONE = "done"
    """``target`` objects are moved: nothing more to select."""


class DecisionMaking(BoxLayer):
    """Selects the objects this robot moves, in agreement with the others (module docs)."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.state = State.SUSPENDED
        self.selected: Sighting | None = None
        self.helping: int | None = None  # the object this robot helps with
        self.candidate: int | None = None  # the object being agreed on now
        self.lost = False  # a lower id selected the candidate meanwhile
        self.unliftable: set[int] = set()

    # -- the rule ---------------------------------------------------------------------------

    def choose(self, here: Point, seen: Sequence[Sighting]) -> list[Sighting]:
        """The objects to try, best first: the nearest, ties by id."""
        return sorted(seen, key=lambda box: (distance(here, (box.x, box.y)), box.obj))

    # -- activation -------------------------------------------------------------------------

    async def inner_process(self) -> None:
        """Activated: with no object selected and nothing under way, select one (Fig. 21)."""
        if self.state is not State.SUSPENDED:
            return
        if self.termination_condition():
            self.state = State.DONE
            return
        self.state = State.SELECTING
        self.send_to_layer(ACTION, Scan())

    async def on_timer(self, key: Hashable) -> None:
        """Time to scan again (the activation that follows does it)."""
        if key == _RESCAN and self.state is State.BACKING_OFF:
            self.state = State.SUSPENDED

    # -- from the layers below --------------------------------------------------------------

    async def store_intra_msg(self, msg: Message) -> None:
        """Scan results, and the Task layer's news."""
        match msg:
            case ScanResult():
                await self._select(msg)
            case MovedCount(moved=moved):
                self.learn_moved(moved)
            case CarryDone(obj=obj) | Released(obj=obj):
                if self._busy_with(obj):
                    self.selected, self.helping = None, None
                    self.state = State.SUSPENDED
            case Helping(obj=obj):
                self._release_selection()
                self.cancel_wake(_RESCAN)
                self.helping, self.state = obj, State.HELPING
            case GiveUp(obj=obj):
                self.unliftable.add(obj)
                if self._busy_with(obj):
                    self._release_selection()
                    self.state = State.SUSPENDED
            case _:
                self.unexpected(msg, "not a message Decision-Making takes from below")

    def _busy_with(self, obj: int) -> bool:
        if self.state is State.SELECTED:
            return self.selected is not None and self.selected.obj == obj
        return self.state is State.HELPING and self.helping == obj

    def _release_selection(self) -> None:
        if self.selected is not None:
            self.send_to_layer(ACTION, Unclaim(self.selected.obj))
            self.selected = None

    async def _select(self, scan: ScanResult) -> None:
        """SelectObject: the first object of the scan the other robots agree to."""
        self.learn_moved(scan.moved)
        if self.state is not State.SELECTING:
            self.late(scan, f"the layer is {self.state.value}")
            return
        if self.termination_condition():
            self.state = State.DONE
            return
        seen = [box for box in scan.objects if box.obj not in self.unliftable]
        for box in self.choose((scan.x, scan.y), seen):
            if not await self._agreed(box.obj):
                continue
            # Selected from now on: another robot asking for it meanwhile is refused.
            self.selected, self.state = box, State.SELECTED
            self.send_to_layer(ACTION, Claim(box.obj))
            taken = await self.request_down(ChangeStatus(box), reply=ChangeStatus)  # InformTask
            if taken.msg_type == MsgType.ACCEPT:
                return
            # The Task layer agreed to help another robot meanwhile; its Helping
            # message follows. Let the object go (and scan again, should none come).
            self._release_selection()
            break
        self.state = State.BACKING_OFF
        self.wake_after(self.params.retry_interval, _RESCAN)

    async def _agreed(self, obj: int) -> bool:
        """Whether every other robot agrees that this robot takes ``obj``."""
        self.candidate, self.lost = obj, False
        try:
            for peer in self.params.peers:
                try:
                    answer = await self.request(
                        peer,
                        SelectedObject(obj),
                        reply=SelectionAnswer,
                        timeout=self.params.timeout,
                        retries=self.params.retries,
                    )
                except RequestTimeout:
                    continue  # a robot that does not answer cannot object
                if answer.msg_type != MsgType.ACCEPT or self.lost:
                    return False
            return not self.lost
        finally:
            self.candidate = None

    # -- from other robots -------------------------------------------------------------------

    def get_msg_reply(self, msg: Message) -> Message | None:
        """Answers another robot's SelectedObject on arrival: is there a conflict?"""
        match msg:
            case SelectedObject(obj=obj):
                return SelectionAnswer(obj, msg_type=self._conflict(msg.robot_id, obj))
        self.unexpected(msg, "not a request Decision-Making answers")
        return None

    def _conflict(self, asker: int, obj: int) -> MsgType:
        if self._busy_with(obj):
            return MsgType.DENY
        if self.candidate == obj:
            if self.robot_id < asker:
                return MsgType.DENY
            self.lost = True  # the lower id wins: let it have the object
        return MsgType.ACCEPT
