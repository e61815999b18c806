"""Where each robot of a Zenoh swarm lives, from liveliness tokens: who may place, move, remove it.

A robot claims a place with a liveliness token, under one of two keys::

    {namespace}/alive/{robot}/{zid}                      unsigned (no swarm key)
    {namespace}/alive/{robot}/{zid}/{stamp}/{proof}      signed (with a swarm key)

``zid`` is the Zenoh id of the session the robot lives in, ``stamp`` when it
claimed the place (:func:`~cas_async._wire._presence.stamp`, microseconds since
the epoch) and ``proof`` the :class:`~cas_async._wire._presence.PresenceSeal`'s
proof of the key without it. Zenoh merges tokens under one key: a token *appears*
when the first session declares the key and *goes* when the last one holding it
undeclares it or dies, so holding a copy of a live token changes nothing (until the
original goes: the copy then keeps it).

:class:`Members` decides, robot by robot, from every live claim it has heard of:

* A robot of this process lives here, whatever other sessions claim.
* Without a seal (no swarm key), the first claim heard places the robot, and it stays
  there while that token lives: another claim, from any other session, is refused
  (``token_conflict``) and kept aside; when the placed token goes, the first claim
  kept aside, if any, takes its place (a robot restarted elsewhere before its old
  token went), else the robot leaves. Only the going of the placed token moves or
  removes the robot.
* With a seal, only claims that verify count (``token_unsigned``, ``token_forged``
  otherwise), and the one with the newest stamp places the robot: a robot restarted
  in another session moves there at once, even while its old session's token lives
  on (a frozen process, until its lease ends). A claim stamped no later than one of
  the robot's that went already is a copy of an old token (``token_replayed``); an
  older one than where the robot lives, ``token_conflict``.

Refused claims are reported through ``on_refused`` (the transport counts them in
its robots' drops, as ``transport.<reason>``); malformed token keys as
``token_malformed``. The claims kept per robot are bounded (:data:`MAX_CLAIMS`).

What a stranger can do: a Zenoh session that reaches the swarm's (Zenoh lets it
declare tokens, subscribe and publish under any key) and has no swarm key.

Without a swarm key, it cannot move or remove a placed robot. It can:

* read every token (one ``liveliness().get``) and every datagram;
* place robots that do not exist (a token under a new id: robots hear it join);
* claim a robot before the robot's own token is heard: the robot's process then
  refuses to open it ("already on the Zenoh swarm"), other processes place it at
  the stranger's session; and a claim it holds takes a robot's place when the
  robot leaves;
* speak for any placed robot: a datagram under a pair's key is the sender's.

With a swarm key (``AuthenticatedTransport`` over the transport), it can neither place,
move nor remove a robot: a token without a proof, or whose proof does not verify (made
up, signed with another key, or a real proof on another robot, session or stamp), is
refused; a copy of a live token is merged into it by Zenoh; a copy of one that went is
refused by every process that saw it go. Nor can it speak for a robot (its datagrams
do not verify). It can still:

* read every token and every datagram (nothing is encrypted);
* hold a copy of a live robot's token: when the robot closes or its process dies,
  the robot then looks present, at its dead session, until the copy goes or the
  robot comes back (a newer token); what is sent to it meanwhile is lost, requests
  to it time out. A copy of the token of a robot that went does the same in a
  process that did not see it go (one started since);
* flood: each token and datagram is refused and counted, at the cost of an HMAC.

Every key holder may claim any robot (the newest claim wins). Stamps are wall-clock
microseconds, as the first counters of authenticated datagrams are: a robot restarted
on a host whose clock is behind the one it left is refused (``token_replayed``) by
processes that saw it go, until that clock passes its old stamp.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, final

from ..._types import RobotId
from ..._wire._presence import PresenceSeal, stamp

__all__ = ["MAX_CLAIMS", "Claim", "Members"]

MAX_CLAIMS: Final = 8
"""Live claims kept per robot; beyond them a claim is refused and forgotten."""

_TAIL: Final = re.compile(
    r"(?P<robot>-?[0-9]{1,19})/(?P<zid>[0-9a-f]{1,32})"
    r"(?:/(?P<stamp>[0-9]{1,20})/(?P<proof>[0-9a-f]{32}))?"
)

Changed = Callable[[RobotId, str | None, str | None], None]
Refused = Callable[[str, str, RobotId | None], None]


@final
@dataclass(frozen=True, slots=True)
class Claim:
    """A robot's claim to live in session ``zid``, as a token key says it."""

    robot: RobotId
    zid: str
    stamp: int  # 0: unsigned
    proof: str  # "": unsigned
    key: str


@final
class Members:
    """The robots of a swarm and the session each lives in, as the tokens prove it.

    Args:
        namespace: the swarm's key prefix.
        on_change: called with ``(robot, before, after)`` when a robot joins
            (``before`` is ``None``), moves, or leaves (``after`` is ``None``).
        on_refused: called with ``(reason, detail, robot)`` for each claim refused
            (``robot`` is ``None`` when the key names none).
    """

    __slots__ = (
        "_claims",
        "_gone",
        "_last_stamp",
        "_local",
        "_on_change",
        "_on_refused",
        "_placed_by",
        "_prefix",
        "_seal",
        "placed",
        "zid",
    )

    def __init__(self, namespace: str, on_change: Changed, on_refused: Refused) -> None:
        self._prefix = f"{namespace}/alive/"
        self._on_change = on_change
        self._on_refused = on_refused
        self._seal: PresenceSeal | None = None
        self.zid = ""
        """This process's session (its tokens' echo is ignored: it knows its robots)."""
        self.placed: dict[RobotId, str] = {}
        """Every robot placed, and its session's zid (one dict for good: never replaced)."""
        self._placed_by: dict[RobotId, Claim] = {}
        self._claims: dict[RobotId, dict[str, Claim]] = {}  # other sessions', by key, in order
        self._local: dict[RobotId, Claim] = {}
        self._gone: dict[RobotId, int] = {}  # with a seal: newest stamp of a claim that went
        self._last_stamp = 0

    @property
    def sealed(self) -> bool:
        """Whether claims must be proven (a swarm key)."""
        return self._seal is not None

    def require(self, seal: PresenceSeal) -> None:
        """From now on only claims that ``seal`` verifies count; those heard are judged again."""
        self._seal = seal
        heard, self._claims = self._claims, {}
        for claims in heard.values():
            for claim in claims.values():
                self.appeared(claim.key)
        for robot in [robot for robot in self.placed if robot not in self._claims]:
            self._settle(robot)

    # -- this process's robots ---------------------------------------------------------

    def attach(self, robot: RobotId) -> str:
        """Robot ``robot`` lives in this process from now on: the key of its token."""
        key = f"{self._prefix}{robot}/{self.zid}"
        when = proof = ""
        if self._seal is not None:
            self._last_stamp = now = stamp(self._last_stamp)
            when = str(now)
            key = f"{key}/{when}"
            proof = self._seal.sign(key)
            key = f"{key}/{proof}"
        self._local[robot] = Claim(robot, self.zid, int(when or 0), proof, key)
        self._settle(robot)
        return key

    def detach(self, robot: RobotId) -> None:
        """Robot ``robot`` no longer lives in this process (its token goes)."""
        claim = self._local.pop(robot, None)
        if claim is not None:
            self._went(claim)
            self._settle(robot)

    def clear(self) -> None:
        """The session closed: nobody is placed, no claim is live (what went is remembered)."""
        self.placed.clear()
        self._placed_by.clear()
        self._claims.clear()
        self._local.clear()
        self.zid = ""

    # -- tokens of other sessions ------------------------------------------------------

    def appeared(self, key: str) -> None:
        """A token appeared under ``key``: a claim, judged and, if it counts, kept."""
        claim = self._read(key)
        if claim is None:
            self._on_refused("token_malformed", f"liveliness token {key!r} is no robot's", None)
            return
        if claim.zid == self.zid:  # the echo of this process's tokens
            return
        refusal = self._unproven(claim)
        if refusal is not None:
            self._on_refused(*refusal, claim.robot)
            return
        claims = self._claims.setdefault(claim.robot, {})
        if key in claims:
            return
        if len(claims) >= MAX_CLAIMS:
            self._refuse_conflict(claim, "kept aside already: forgotten")
            return
        claims[key] = claim
        self._settle(claim.robot, claim)

    def went(self, key: str) -> None:
        """The token under ``key`` went (its last holder undeclared it, or died)."""
        claim = self._read(key)
        if claim is None or claim.zid == self.zid:
            return
        claims = self._claims.get(claim.robot)
        if claims is None or claims.pop(key, None) is None:
            return  # a claim refused, or never heard
        if not claims:
            del self._claims[claim.robot]
        self._went(claim)
        self._settle(claim.robot)

    # -- deciding ----------------------------------------------------------------------

    def _read(self, key: str) -> Claim | None:
        if not key.startswith(self._prefix):
            return None
        match = _TAIL.fullmatch(key, len(self._prefix))
        if match is None:
            return None
        when, proof = match["stamp"], match["proof"]
        return Claim(int(match["robot"]), match["zid"], int(when or 0), proof or "", key)

    def _unproven(self, claim: Claim) -> tuple[str, str] | None:
        """Why a claim does not count (with a seal), or ``None``."""
        seal = self._seal
        if seal is None:
            return None
        robot, zid = claim.robot, claim.zid
        if not claim.proof:
            return (
                "token_unsigned",
                f"robot {robot}: the token of session {zid} has no proof of presence "
                "(a swarm key is required)",
            )
        if not seal.verifies(claim.key[: -len(claim.proof) - 1], claim.proof):
            return (
                "token_forged",
                f"robot {robot}: the token of session {zid} does not verify: forged, or "
                "signed with another swarm key",
            )
        gone = self._gone.get(robot)
        if gone is not None and claim.stamp <= gone:
            return (
                "token_replayed",
                f"robot {robot}: the token of session {zid} is stamped {claim.stamp}, no later "
                f"than one of the robot's that went ({gone}): a copy of an old token",
            )
        return None

    def _went(self, claim: Claim) -> None:
        """With a seal: no claim of the robot as old as ``claim`` counts any more."""
        robot = claim.robot
        if self._seal is None or claim.stamp <= self._gone.get(robot, 0):
            return
        self._gone[robot] = claim.stamp
        claims = self._claims.get(robot)
        if claims:
            for key in [key for key, kept in claims.items() if kept.stamp <= claim.stamp]:
                del claims[key]
            if not claims:
                del self._claims[robot]

    def _choose(self, robot: RobotId) -> Claim | None:
        local = self._local.get(robot)
        if local is not None:
            return local
        claims = self._claims.get(robot)
        if not claims:
            return None
        current = self._placed_by.get(robot)
        if self._seal is None:  # the first claim stays while it lives
            if current is not None and current.key in claims:
                return current
            return next(iter(claims.values()))
        newest = max(claims.values(), key=lambda claim: claim.stamp)
        if current is not None and current.key in claims and current.stamp >= newest.stamp:
            return current
        return newest

    def _settle(self, robot: RobotId, arrived: Claim | None = None) -> None:
        """Places ``robot`` where its claims say; refuses ``arrived`` if it lost."""
        chosen = self._choose(robot)
        if arrived is not None and (chosen is None or chosen.key != arrived.key):
            where = "this process" if chosen is None or chosen.zid == self.zid else chosen.zid
            self._refuse_conflict(arrived, f"it lives in session {where}")
        before = self.placed.get(robot)
        if chosen is None:
            self._placed_by.pop(robot, None)
            if before is not None:
                del self.placed[robot]
                self._on_change(robot, before, None)
            return
        self._placed_by[robot] = chosen
        if before != chosen.zid:
            self.placed[robot] = chosen.zid
            self._on_change(robot, before, chosen.zid)

    def _refuse_conflict(self, claim: Claim, why: str) -> None:
        self._on_refused(
            "token_conflict",
            f"robot {claim.robot}: the token of session {claim.zid} is refused: {why}",
            claim.robot,
        )
