"""The keys datagrams travel under, declared to Zenoh on both sides so it routes them fast.

A datagram from ``sender`` to ``receiver`` (in session ``zid``) goes under the key
``{namespace}/d/{zid}/{receiver}/{sender}``; a session subscribes to
``{namespace}/d/{zid}/*/*``. Measured on loopback (Zenoh 1.10, 2 cores):

* Sending: ``session.put`` under a key expression resolves the key's routes on every
  put; a publisher declared for the key resolves them once. Its put took 1.4 µs
  against 6.2 µs (median, in a robot's send), and robots' one-way throughput rose by
  about 30%. :class:`Publishers` declares one per pair of robots that talk.
* Receiving: a wildcard subscriber costs Zenoh's network thread about 3-4 µs per
  sample to match the key, against 0.4-1 µs for an exact one; declaring the key on
  the receiving session (``declare_keyexpr``) brings it back to the exact cost.
  :class:`ReceivedKeys` declares the keys of the pairs it hears from.

Declarations cost memory (about 2 KB each) and each one takes longer the more the
session holds (a publisher: 12 µs at 100, 230 µs at 600, 1.6 ms at 10,000; a key
expression: 10 µs at 200, 50 µs at 1,000), so each side declares at most
:data:`DECLARED` keys: the first pairs that talk get them, later pairs go through the
session undeclared (correct, only slower). A declaration is dropped, and its place
freed, when one of its two robots leaves.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable
from typing import Any, Final

from ..._types import RobotId

__all__ = [
    "APPEARED",
    "DECLARED",
    "GONE",
    "KNOWN_KEYS",
    "LOCAL",
    "REMOTE",
    "Entry",
    "Publishers",
    "ReceivedKeys",
    "pair_of",
    "subscribe",
]

DECLARED: Final = 256
"""Keys a session declares at most, for sending and again for receiving."""
KNOWN_KEYS: Final = 4096
"""Received keys whose pair of robots is remembered (forgotten all at once beyond)."""

Put = Callable[[bytes], object]
Pair = tuple[RobotId, RobotId]  # (receiver, sender)

# What the subscribers hand to the loop: (kind, what, payload). REMOTE: a datagram from
# another process, ``what`` is its key; LOCAL: from this process (never through Zenoh),
# ``what`` is (receiver, sender); APPEARED / GONE: a liveliness token, under its key.
REMOTE: Final = 0
LOCAL: Final = 1
APPEARED: Final = 2
GONE: Final = 3
Entry = tuple[int, Any, bytes]


def subscribe(
    zenoh: Any,
    session: Any,
    namespace: str,
    zid: str,
    put: Callable[[Entry], None],
    subscribers: list[Any],
) -> None:
    """Declares a session's two subscribers, appended to ``subscribers``; both call ``put``.

    The datagrams of the session (``{namespace}/d/{zid}/*/*``; other shapes are no
    datagram keys) come on the subscriber's own thread; every robot's token
    (``{namespace}/alive/**``, those alive already included) on Zenoh's network
    thread (``indirect=False``), so a token is handed over before any datagram its
    robot sent after declaring it.
    """
    subscribers.append(
        session.declare_subscriber(
            f"{namespace}/d/{zid}/*/*",
            lambda sample: put((REMOTE, str(sample.key_expr), sample.payload.to_bytes())),
        )
    )
    put_kind = zenoh.SampleKind.PUT
    subscribers.append(
        session.liveliness().declare_subscriber(
            f"{namespace}/alive/**",
            zenoh.handlers.Callback(
                lambda sample: put(
                    (APPEARED if sample.kind == put_kind else GONE, str(sample.key_expr), b"")
                ),
                indirect=False,
            ),
            history=True,
        )
    )


def pair_of(key: str) -> Pair | None:
    """The ``(receiver, sender)`` a datagram key names, or ``None`` if it names no robots."""
    *_, to, by = key.rsplit("/", 2)
    try:
        return int(to), int(by)
    except ValueError:
        return None


class Publishers:
    """How each pair of robots puts its datagrams into one session.

    Args:
        zenoh: the ``zenoh`` module.
        session: the open session (closing it undeclares every publisher).
        namespace: the transport's key prefix.
        budget: publishers to declare at most.
    """

    __slots__ = ("_budget", "_declared", "_options", "_pairs", "_prefix", "_session", "_zenoh")

    def __init__(self, zenoh: Any, session: Any, namespace: str, budget: int = DECLARED) -> None:
        self._zenoh = zenoh
        self._session = session
        self._prefix = f"{namespace}/d/"
        # Reliable: a full queue makes the sender wait instead of dropping (Zenoh's
        # default, DROP, lost 22% of a burst in one process).
        self._options = {"congestion_control": zenoh.CongestionControl.BLOCK}
        self._budget = budget
        # receiver -> sender -> (the receiver's session, the put, its publisher or None)
        self._pairs: dict[RobotId, dict[RobotId, tuple[str, Put, Any]]] = {}
        self._declared: dict[RobotId, set[RobotId]] = {}  # sender -> receivers with a publisher

    def put_for(self, zid: str, receiver: RobotId, sender: RobotId) -> Put:
        """What puts a datagram from ``sender`` to ``receiver``, who lives in session ``zid``."""
        pairs = self._pairs.get(receiver)
        if pairs is not None:
            route = pairs.get(sender)
            if route is not None and route[0] == zid:
                return route[1]
        return self._route(zid, receiver, sender)

    def _route(self, zid: str, receiver: RobotId, sender: RobotId) -> Put:
        self._forget(receiver, sender)  # a route to the session the receiver left, if any
        key = f"{self._prefix}{zid}/{receiver}/{sender}"
        publisher = None
        put: Put
        if self._budget > 0:
            publisher = self._session.declare_publisher(key, **self._options)
            self._budget -= 1
            self._declared.setdefault(sender, set()).add(receiver)
            put = publisher.put
        else:
            put = functools.partial(self._session.put, self._zenoh.KeyExpr(key), **self._options)
        self._pairs.setdefault(receiver, {})[sender] = (zid, put, publisher)
        return put

    def forget_receiver(self, receiver: RobotId) -> None:
        """``receiver`` left or moved: its routes go, its publishers are undeclared."""
        for sender in list(self._pairs.get(receiver, ())):
            self._forget(receiver, sender)

    def forget_sender(self, sender: RobotId) -> None:
        """``sender``'s endpoint closed: its publishers are undeclared."""
        for receiver in list(self._declared.get(sender, ())):
            self._forget(receiver, sender)

    def _forget(self, receiver: RobotId, sender: RobotId) -> None:
        pairs = self._pairs.get(receiver)
        route = None if pairs is None else pairs.pop(sender, None)
        if pairs is not None and not pairs:
            del self._pairs[receiver]
        if route is None or route[2] is None:
            return
        receivers = self._declared[sender]
        receivers.discard(receiver)
        if not receivers:
            del self._declared[sender]
        self._budget += 1
        with contextlib.suppress(Exception):  # the session is closing: it undeclares it
            route[2].undeclare()

    def declared(self) -> int:
        """How many publishers the session holds for datagrams now."""
        return sum(len(receivers) for receivers in self._declared.values())


class ReceivedKeys:
    """The pair of robots each received key names, read once; some keys declared.

    :attr:`pairs` maps every key read so far to its ``(receiver, sender)``; it is
    emptied when it reaches :data:`KNOWN_KEYS` (anyone may publish under any key, so
    it must stay bounded). :meth:`declare` declares a key to the session. When a robot
    joins or leaves, :meth:`forget` drops the keys that name it: they are read, and
    weighed for declaring, again.

    Args:
        session: the open session (closing it undeclares every key).
        budget: keys to declare at most.
    """

    __slots__ = ("_budget", "_declared", "_keys_of", "_session", "pairs")

    def __init__(self, session: Any, budget: int = DECLARED) -> None:
        self._session = session
        self._budget = budget
        self.pairs: dict[str, Pair] = {}
        self._keys_of: dict[RobotId, set[str]] = {}  # robot -> keys of pairs that name it
        self._declared: dict[str, tuple[Pair, Any]] = {}  # key -> (its pair, key expression)

    def read(self, key: str) -> Pair | None:
        """The ``(receiver, sender)`` of a datagram key (remembered), or ``None``."""
        pair = pair_of(key)
        if pair is None:
            return None
        if len(self.pairs) >= KNOWN_KEYS:
            self.pairs.clear()
            self._keys_of.clear()
        self.pairs[key] = pair
        for robot_id in pair:
            self._keys_of.setdefault(robot_id, set()).add(key)
        return pair

    def declare(self, key: str, pair: Pair) -> None:
        """Declares ``key`` (of ``pair``) to the session, while the budget lasts."""
        if self._budget > 0 and key not in self._declared:
            self._declared[key] = (pair, self._session.declare_keyexpr(key))
            self._budget -= 1

    def forget(self, robot_id: RobotId) -> None:
        """``robot_id`` joined or left: keys naming it are read again, and undeclared."""
        for key in self._keys_of.pop(robot_id, ()):
            self.pairs.pop(key, None)
        gone = [key for key, (pair, _) in self._declared.items() if robot_id in pair]
        for key in gone:
            _, expression = self._declared.pop(key)
            self._budget += 1
            with contextlib.suppress(Exception):  # the session is closing: it undeclares it
                self._session.undeclare(expression)

    def declared(self) -> int:
        """How many received keys the session holds declared now."""
        return len(self._declared)
