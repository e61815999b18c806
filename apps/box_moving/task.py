"""The Task layer (thesis §4.4: HelpRequest, InformCoordination).

On ``ChangeStatus`` from Decision-Making (a request: it is answered ACCEPT,
taken on, or DENY, when this robot has just agreed to help another),
HelpRequest decides from the robot's payload whether the object can be moved
alone. If so, it informs Coordination of a solo carry (InformCoordination:
``Assignment``). If not, it asks the other robots, nearest first, for help
(``RequestPartner``), one at a time, until one accepts; this robot then leads
the joint carry, and informs Coordination. When all refuse, it asks again
after ``retry_interval``; when none of them could lift the object even
together with this robot, it gives the object up (``GiveUp`` to
Decision-Making, which selects another).

Answering another robot's ``RequestPartner`` (at once, on arrival, even while
this layer waits for answers of its own): ACCEPT when the pair can lift the
object and this robot is free, or is itself waiting for a partner and the
asker has the lower id (it drops its own selection: of two robots waiting for
each other, the lower id's request wins, so they never both wait). The
helper's Task tells Decision-Making (``Helping``: release any selection) and
Coordination (``Assignment`` as helper). A busy robot refuses but remembers
the asker; once its carry is done it offers its help (``OfferHelp``), before
Decision-Making selects anything new, so a robot that needs a partner is not
starved by one that always finds something to carry alone.

A leader that got a second ACCEPT, or became a helper meanwhile, sends
``Dismiss`` to the robot it no longer needs. Completions from below
(``CarryDone``, ``MovedCount``) go up to Decision-Making.
"""

from __future__ import annotations

import enum
from collections.abc import Hashable

from cas_async import Message, MsgType, RequestTimeout

from .base import ACTION, BoxLayer, Params
from .messages import (
    Assignment,
    CarryDone,
    ChangeStatus,
    Dismiss,
    Dismissed,
    GiveUp,
    Helping,
    Locate,
    Located,
    MovedCount,
    OfferHelp,
    PartnerAnswer,
    Released,
    RequestPartner,
    Role,
    Sighting,
)

__all__ = ["Phase", "Task"]


class Phase(enum.Enum):
    """What the Task layer is doing."""

    IDLE = "idle"
    """Nothing to carry: free to help."""
    SOLO = "solo"
    """Carrying an object alone."""
    WAITING = "waiting"
    """Looking for a partner for its selected object."""
    LEADING = "leading"
    """Carrying its object with a partner."""
    HELPING = "helping"
    """Carrying another robot's object with it."""
    OFFERING = "offering"
    """Just free again: offering help to the robots it refused."""


class Task(BoxLayer):
    """Decides how each object is carried and finds partners; see the module docs."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.phase = Phase.IDLE
        self.object: Sighting | None = None  # what this robot carries, or helps carry
        self.partner = 0
        self.asked_by: dict[int, RequestPartner] = {}  # refused while busy: offered help later

    # -- from Decision-Making ---------------------------------------------------------------

    async def store_intra_msg(self, msg: Message) -> None:
        """ChangeStatus from above; completions from below."""
        match msg:
            case ChangeStatus(object=box):  # told, not asked: taken the same way
                self._help_request(box)
            case CarryDone(obj=obj):
                await self._done(obj)
            case MovedCount(moved=moved):
                if self.learn_moved(moved):
                    self.send_up(MovedCount(moved))
            case _:
                self.unexpected(msg, "not a message Task takes from its neighbours")

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """Answers Decision-Making's ChangeStatus: ACCEPT (taken on) or DENY (busy helping)."""
        match msg:
            case ChangeStatus(object=box):
                return ChangeStatus(box, msg_type=self._help_request(box))
        self.unexpected(msg, "not a request Task answers")
        return None

    def _help_request(self, box: Sighting) -> MsgType:
        """HelpRequest: alone if the payload allows, else a partner is needed; whether taken on."""
        if self.phase is not Phase.IDLE:
            # This robot agreed to help another since Decision-Making last heard from
            # it: the Helping message on its way makes Decision-Making let go.
            self.late(ChangeStatus(box), f"this robot is {self.phase.value}")
            return MsgType.DENY
        self.object, self.partner = box, 0
        if self.params.lifts_alone(box.weight):
            self.phase = Phase.SOLO
            self.send_down(Assignment(box, Role.SOLO))  # InformCoordination
            return MsgType.ACCEPT
        self.phase = Phase.WAITING
        # Asked from the timer, not here: Decision-Making waits for this answer.
        self.wake_after(0.0, ("ask", box.obj))
        return MsgType.ACCEPT

    def _waiting_for(self, obj: int) -> bool:
        return self.phase is Phase.WAITING and self.object is not None and self.object.obj == obj

    async def _ask(self, box: Sighting) -> None:
        """Asks the other robots for help, nearest first, until one accepts."""
        located = await self.request_layer(ACTION, Locate(), reply=Located)
        peers = set(self.params.peers)
        could = False  # whether any robot could lift it with this one, or did not answer
        for peer in (robot for robot in located.ids if robot in peers):
            if not self._waiting_for(box.obj):
                return
            try:
                answer = await self.request(
                    peer,
                    RequestPartner(box, self.params.payload),
                    reply=PartnerAnswer,
                    timeout=self.params.timeout,
                    retries=self.params.retries,
                )
            except RequestTimeout:
                could = True
                continue
            accepted = answer.msg_type == MsgType.ACCEPT
            if not self._waiting_for(box.obj):  # a partner found us meanwhile
                if accepted:
                    await self._dismiss(peer, box.obj)
                return
            if accepted:
                self._lead(box, peer, answer.payload)
                return
            could = could or answer.able
        if could:
            self.wake_after(self.params.retry_interval, ("ask", box.obj))
            return
        self.phase, self.object = Phase.IDLE, None
        self.send_up(GiveUp(box.obj))

    def _lead(self, box: Sighting, partner: int, payload: float) -> None:
        self.cancel_wake(("ask", box.obj))
        self.phase, self.object, self.partner = Phase.LEADING, box, partner
        self.send_down(Assignment(box, Role.LEADER, partner, payload))  # InformCoordination

    async def _dismiss(self, peer: int, obj: int) -> None:
        try:
            await self.request(
                peer,
                Dismiss(obj),
                reply=Dismiss,
                timeout=self.params.timeout,
                retries=self.params.retries,
            )
        except RequestTimeout:
            self.log.warning("robot %d never confirmed it was dismissed from object %d", peer, obj)

    async def on_timer(self, key: Hashable) -> None:
        """Asks for a partner (again)."""
        match key:
            case ("ask", int(obj)) if self._waiting_for(obj) and self.object is not None:
                await self._ask(self.object)

    async def _done(self, obj: int) -> None:
        """A carry is over: offer help to the robots refused meanwhile, then report up."""
        if self.object is not None and self.object.obj == obj:
            self.phase, self.object, self.partner = Phase.OFFERING, None, 0
            await self._offer()
            if self.phase is Phase.OFFERING:
                self.phase = Phase.IDLE
        self.send_up(CarryDone(obj))

    async def _offer(self) -> None:
        while self.asked_by and self.phase is Phase.OFFERING:
            asker = min(self.asked_by)  # the lowest id first, as when requests cross
            request = self.asked_by.pop(asker)
            box = request.object
            try:
                answer = await self.request(
                    asker,
                    OfferHelp(box.obj, self.params.payload),
                    reply=OfferHelp,
                    timeout=self.params.timeout,
                    retries=self.params.retries,
                )
            except RequestTimeout:
                continue
            if answer.msg_type == MsgType.ACCEPT and self.phase is Phase.OFFERING:
                self._help(asker, box, request.payload)

    def _help(self, leader: int, box: Sighting, payload: float) -> None:
        """This robot helps ``leader`` with ``box``: tell the layers above and below."""
        if self.phase is Phase.WAITING and self.object is not None:
            self.cancel_wake(("ask", self.object.obj))
        self.phase, self.object, self.partner = Phase.HELPING, box, leader
        self.asked_by.pop(leader, None)
        self.send_up(Helping(box.obj, leader))
        self.send_down(Assignment(box, Role.HELPER, leader, payload))

    # -- from other robots -------------------------------------------------------------------

    def get_msg_reply(self, msg: Message) -> Message | None:
        """Answers RequestPartner, OfferHelp and Dismiss on arrival (see the module docs)."""
        match msg:
            case RequestPartner():
                return self._answer(msg)
            case OfferHelp(obj=obj, payload=payload):
                if self._waiting_for(obj) and self.object is not None:
                    self._lead(self.object, msg.robot_id, payload)
                    return OfferHelp(obj, self.params.payload)
                return OfferHelp(obj, self.params.payload, msg_type=MsgType.DENY)
            case Dismiss(obj=obj):
                self._dismissed(msg.robot_id, obj)
                return Dismiss(obj)
        self.unexpected(msg, "not a request Task answers")
        return None

    def _answer(self, request: RequestPartner) -> PartnerAnswer:
        box, asker = request.object, request.robot_id
        able = self.params.payload + request.payload >= box.weight
        free = self.phase is Phase.IDLE or (self.phase is Phase.WAITING and asker < self.robot_id)
        if not (able and free):
            if able and self.phase is not Phase.WAITING:
                self.asked_by[asker] = request  # busy now: offer help once free
            return PartnerAnswer(box.obj, able, self.params.payload, msg_type=MsgType.DENY)
        self._help(asker, box, request.payload)
        return PartnerAnswer(box.obj, True, self.params.payload)

    def _dismissed(self, leader: int, obj: int) -> None:
        if (
            self.phase is Phase.HELPING
            and self.partner == leader
            and self.object is not None
            and self.object.obj == obj
        ):
            self.phase, self.object, self.partner = Phase.IDLE, None, 0
            self.send_down(Dismissed(obj))
            self.send_up(Released(obj))
