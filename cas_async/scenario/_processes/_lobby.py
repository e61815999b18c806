"""The world's lobby: where workers ask to join a run, and learn their place in it.

A worker sends :class:`~._control.Hello` under ``hello/<nonce>`` (its own random
nonce) until it is answered under ``welcome/<nonce>``: :class:`~._control.Welcome`
(its index, the run's namespace, the scenario and every worker's share of the
robots) while there are places, :class:`~._control.Full` after. A hello older than
:data:`HELLO_AGE` is a replay, refused. A hello whose tag does not check against
the world's key gets :class:`~._control.Refused`, which the worker cannot check
either: it learns that the keys differ, and says so (see :func:`~._joining.join`),
and the world says once that a worker's hello did not check.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any, Final, final

from ..._wire._swarm_key import SwarmKey
from .._spec._loader import Scenario
from ._control import WORLD, Channel, Control, Full, Hello, Refused, Welcome

__all__ = ["HELLO_AGE", "LOBBY", "Lobby"]

LOBBY: Final = "cas_async/lobby"
"""The lobby's key prefix (the same for every run: a worker knows no run yet)."""
HELLO_AGE: Final = 30.0
"""Wall seconds a worker's hello stays fresh (an older one is a replay)."""

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
    ) -> None:
        self._scenario = scenario
        self._workers = workers
        self._namespace = namespace
        self._shares = shares
        self._joined = joined
        self._places: dict[str, int] = {}  # a hello's nonce -> the place it took
        self._said_key = False  # that a hello did not check against the key
        self._channel = Channel(session, LOBBY, WORLD, key, self._on_hello, self._on_refused)
        self._channel.listen("hello/*")

    @property
    def refused(self) -> dict[str, int]:
        """Lobby messages refused, by reason (``control.<reason>``)."""
        return dict(self._channel.refused)

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
