"""The world's lobby: where workers ask to join a run, and learn their place in it.

A worker sends :class:`~._control.Hello` under ``hello/<nonce>`` (its own random
nonce) until it is answered under ``welcome/<nonce>``: :class:`~._control.Welcome`
(its index, the run's namespace, the scenario and every worker's share of the
robots) while there are places, :class:`~._control.Full` after. A hello older than
:data:`HELLO_AGE` is a replay, refused. A hello whose tag does not check against
the world's key gets :class:`~._control.Refused`, which the worker cannot check
either: it learns that the keys differ, and says so (see :func:`~._joining.join`),
and the world says once that a worker's hello did not check.

Each world's lobby is its own: its keys are under ``cas_async/lobby/<the world's
Zenoh id>`` (:func:`lobby_of`), which a worker reads from the router it connected
to, and a message's tag covers its key. So a hello signed for one world checks in
no other, even one with the same key: captured in one lobby and put into another,
it is refused as unsigned. A flood of hellos that do not check costs the world a
signed :class:`~._control.Refused` for at most :data:`REFUSALS_PER_SECOND` a
second (a burst of :data:`REFUSAL_BURST`), and one per nonce a second; the others
are counted (``control.refusal_suppressed``) and not answered.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import Any, Final, final

from ..._wire._swarm_key import SwarmKey
from .._spec._loader import Scenario
from ._control import WORLD, Channel, Control, Full, Hello, Refused, Welcome

__all__ = ["HELLO_AGE", "LOBBY", "REFUSALS_PER_SECOND", "REFUSAL_BURST", "Lobby", "lobby_of"]

LOBBY: Final = "cas_async/lobby"
"""The prefix of every world's lobby (a worker knows no run yet, only its world)."""
HELLO_AGE: Final = 10.0
"""Wall seconds a worker's hello stays fresh (an older one is a replay)."""
REFUSALS_PER_SECOND: Final = 10.0
"""Hellos that do not check answered with a :class:`Refused` a second, at most."""
REFUSAL_BURST: Final = 20
"""Of which this many at once."""
_REFUSAL_PER_NONCE: Final = 1.0
"""Wall seconds between two refusals of one nonce's hellos (a worker says hello 4 times a s)."""


def lobby_of(world: str) -> str:
    """The key prefix of the lobby of the world whose Zenoh session id is ``world``."""
    return f"{LOBBY}/{world}"


Joined = Callable[[int, int], None]
"""``joined(pid, index)``: the worker process ``pid`` took place ``index``."""


@final
class Lobby:
    """The world's side of the lobby (see the module docs).

    Args:
        session: the world's open Zenoh session.
        key: the swarm key the hellos must be signed with.
        scenario: what the welcome carries.
        workers: how many places there are.
        namespace: the run's key prefix, for the welcome.
        shares: every worker's robots, for the welcome (asked at each welcome).
        joined: told when a worker takes a place.
        clock: the wall clock, in seconds (the refusals' rate).
    """

    def __init__(
        self,
        session: Any,
        key: SwarmKey | None,
        scenario: Scenario,
        workers: int,
        namespace: str,
        shares: Callable[[], list[list[int]]],
        joined: Joined,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._scenario = scenario
        self._workers = workers
        self._namespace = namespace
        self._shares = shares
        self._joined = joined
        self._clock = clock
        self._places: dict[str, int] = {}  # a hello's nonce -> the place it took
        self._said_key = False  # that a hello did not check against the key
        self._tokens = float(REFUSAL_BURST)  # refusals that may go now (a token bucket)
        self._filled = clock()  # when the bucket was last topped up
        self._refused_nonces: dict[str, float] = {}  # nonce -> when last refused (recent only)
        self._suppressed = 0
        self.prefix = lobby_of(str(session.zid()))
        """Where this world's lobby is: :func:`lobby_of` the world's session."""
        self._channel = Channel(session, self.prefix, WORLD, key, self._on_hello, self._on_refused)
        self._channel.listen("hello/*")

    @property
    def refused(self) -> dict[str, int]:
        """Lobby messages refused, by reason (``control.<reason>``).

        With the refusals not answered (``control.refusal_suppressed``).
        """
        refused = dict(self._channel.refused)
        if self._suppressed:
            refused["control.refusal_suppressed"] = self._suppressed
        return refused

    def close(self) -> None:
        """Stops answering (idempotent)."""
        self._channel.close()

    def _on_hello(self, suffix: str, sender: int, message: Control) -> None:
        match message:
            case Hello(nonce=nonce, sent=sent, pid=pid) if suffix == f"hello/{nonce}":
                if abs(time.time() - sent) > HELLO_AGE:
                    raise ValueError("a stale hello (a replay?)")
                index = self._places.get(nonce)
                if index is None and len(self._places) < self._workers:
                    index = self._places[nonce] = len(self._places)
                    self._joined(pid, index)
                if index is None:
                    self._channel.send(f"welcome/{nonce}", Full(self._workers))
                    return
                scenario = self._scenario
                self._channel.send(
                    f"welcome/{nonce}",
                    Welcome(
                        index, self._namespace, str(scenario.path), scenario.data, self._shares()
                    ),
                )

    def _on_refused(self, suffix: str, reason: str) -> None:
        """A hello that did not check: its sender is told (it learns the keys differ)."""
        nonce = suffix.removeprefix("hello/")
        if suffix == nonce or reason not in ("unsigned", "malformed"):
            return
        if len(nonce) == 16 and all(c in "0123456789abcdef" for c in nonce):
            if not self._may_refuse(nonce):
                self._suppressed += 1
                return
            self._channel.send(
                f"welcome/{nonce}", Refused("the hello does not check against the key")
            )
            if not self._said_key:
                self._said_key = True
                print(
                    "world: a worker's hello does not check against this world's key: "
                    "start every worker with the world's key file",
                    file=sys.stderr,
                )

    def _may_refuse(self, nonce: str) -> bool:
        """Whether a refusal may go to ``nonce`` now (see the module docs); takes its token."""
        now = self._clock()
        self._tokens = min(
            float(REFUSAL_BURST), self._tokens + (now - self._filled) * REFUSALS_PER_SECOND
        )
        self._filled = now
        if now - self._refused_nonces.get(nonce, -math.inf) < _REFUSAL_PER_NONCE:
            return False
        if self._tokens < 1.0:
            return False
        self._tokens -= 1.0
        if len(self._refused_nonces) >= 4 * REFUSAL_BURST:  # forget the ones refused long ago
            self._refused_nonces = {
                n: t for n, t in self._refused_nonces.items() if now - t < _REFUSAL_PER_NONCE
            }
        self._refused_nonces[nonce] = now
        return True
