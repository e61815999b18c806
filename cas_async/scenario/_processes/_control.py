"""The control plane of a run across processes: typed messages, signed, never replayed.

Every process of a run across processes (the world and its workers) speaks these
msgspec Structs, one tagged union, over Zenoh. Each travels in an envelope that
names the run, the sender and the sender's count of messages so far, and with a
swarm key carries an HMAC-SHA256 tag over the key expression and the envelope:

* a message of another run, or one whose tag does not check, is refused;
* a message whose count is not above the last one taken from its sender under
  its key is a replay, refused and counted (a sender's count only grows; the tag
  covers the key, so a replay keeps it; under two keys, two subscriptions may
  deliver a sender's messages a little out of order);
* a message that does not decode, or that its handler cannot apply, is refused
  and counted, and the rest of the batch goes on.

The refusals are counted by reason in :attr:`Channel.refused` (they end up in
``results.json``). Without a key a stranger on the Zenoh network can speak for
anyone (see the README's security section): :class:`Channel` checks what it can
(run, counts, types), and the world refuses to run across hosts without a key.

The protocol (world ``W``, workers ``0..n-1``):

* lobby: a worker sends :class:`Hello` (under ``hello/<nonce>``) until ``W``
  answers :class:`Welcome` (the run's namespace, the scenario, the worker's share
  of the robots) or :class:`Full` under ``welcome/<nonce>``; a hello whose tag
  does not check gets :class:`Refused`, which the worker cannot check either: the
  keys differ, and it says so at once;
* ``W`` sends :class:`Go` when every worker is :class:`Ready`;
* virtual time: each worker runs in windows of its own. When every event of its
  robots before a window's end has run, it publishes its :class:`Window` (what
  its robots did, what they sent to other processes' robots, its next event, the
  window's end ``until``) to ``W`` and to the other workers, with a *promise*:
  nothing it does from now on reaches another worker before it (the soonest of
  its next event, of what the workers it depends on promised, of the next epoch's
  start and of ``run.max_time``, plus the latency). Its next window ends at the
  least promise of the workers it depends on (every other one without an
  interaction range; with one, those of its halo, :mod:`._halo`), at the end of
  the step of ``run.credit`` it is in, or at ``run.max_time``: per-neighbour
  promises, the null messages of Chandy-Misra-Bryant, so a worker far from the
  others runs ahead. Where windows end depends only on the run's events and the
  steps, never on when a message came, so every number of processes gives the
  same run. A worker runs no step past ``W``'s :class:`Grant`, which ``W`` sends
  as it observes: two steps past the one it observed, so ``W`` is not on the
  workers' way. ``W`` observes every record before the least ``until`` of all
  workers; once it decided the run in step ``c`` (its objective met, or every
  robot stopped) the run ends at the end of step ``c + 1`` (as in one process),
  and it says :class:`Stop` once every worker reached that instant. When no
  worker has an event before ``run.max_time`` and nothing is in flight, the run
  has timed out at once; a worker whose windows reached ``run.max_time`` waits
  for the :class:`Stop`;
* epochs (with an interaction range): windows also end at every epoch's start,
  where each worker's window carries its robots' ``cells``; from the cells at
  an epoch's start each worker decides whom it depends on, and whose robots it
  watches, in the epoch after;
* scaled time: workers publish :class:`Window` records as they go, unnumbered;
* a worker that fails says :class:`Failed`; a stopping one says :class:`Bye`
  with its counts.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import hmac
from collections.abc import Callable
from typing import Annotated, Any, Final, Union

import msgspec

from ..._wire._message import finite
from ..._wire._swarm_key import SwarmKey
from ...transport.zenoh import ThreadInbox
from ._observer import Observation

__all__ = [
    "BEAT_EVERY",
    "HURRY_LIMIT",
    "SUSPECT_LIMIT",
    "WORLD",
    "Beat",
    "Bye",
    "Channel",
    "Control",
    "Counts",
    "Failed",
    "Full",
    "Go",
    "Grant",
    "Hello",
    "Ready",
    "Refused",
    "Remote",
    "Stop",
    "Welcome",
    "Window",
    "token_lives",
]

WORLD: Final = -1
"""The world's sender id (workers are ``0..n-1``)."""
HURRY_LIMIT: Final = 0.5
"""Wall seconds the world waits for its workers' last counts, and for its child workers
to exit, when the run was stopped (a signal ends a run within about a second): the
counts it has are at most a second old (workers report every second)."""
BEAT_EVERY: Final = 0.5
"""Wall seconds between two :class:`Beat` of the world."""
SUSPECT_LIMIT: Final = 2.0
"""Wall seconds a process whose liveliness token went has to prove it lives (a signed
message): a token is a hint that a process is gone, never proof (anyone on the
network may say what they like about tokens)."""
_TAG: Final = 16

_MATCHING_POLL: Final = 0.01
"""Wall seconds between two looks at whether a publisher has a subscriber."""


class Remote(msgspec.Struct, frozen=True, array_like=True):
    """An effect on another process's robot, due at loop instant ``at`` (see ``_network``).

    ``kind`` is a :mod:`cas_async._time._deliveries` kind; ``sender`` and ``n`` order the
    effects of one instant; the fields that follow are the kind's.
    """

    at: float
    kind: int
    sender: int
    n: int
    receiver: int
    data: bytes = b""
    item: int = 0
    sent: float = 0.0
    reach: float = 0.0
    answer: int = 0
    refused: str | None = None


class Counts(msgspec.Struct, frozen=True, array_like=True):
    """A worker's counts so far: messages by kind and class, drops, refusals, faults."""

    internal: dict[str, int] = msgspec.field(default_factory=dict)
    external: dict[str, int] = msgspec.field(default_factory=dict)
    dropped: dict[str, int] = msgspec.field(default_factory=dict)
    refused: dict[str, int] = msgspec.field(default_factory=dict)
    faults: dict[str, int] | None = None
    """The ``[faults]`` wire's counts (:attr:`FaultyTransport.stats`), if it has faults."""
    late: int = 0
    """Scaled time: effects from other workers that came after their instant."""
    most_late: float = 0.0
    """Scaled time: wall seconds the latest of them came after its instant."""


class Hello(msgspec.Struct, frozen=True, tag="hello"):
    """A worker asks to join: ``nonce`` (where the answer goes), ``sent`` (wall time), its pid."""

    nonce: str
    sent: float
    pid: int


class Welcome(msgspec.Struct, frozen=True, tag="welcome"):
    """The world takes a worker: its index, the run's namespace and scenario, every share.

    ``shares[k]`` are the robots worker ``k`` runs (``shares[index]`` this one's).
    """

    index: int
    namespace: str
    path: str
    data: dict[str, Any]
    shares: list[list[int]]


class Full(msgspec.Struct, frozen=True, tag="full"):
    """The world has all its workers."""

    workers: int


class Ready(msgspec.Struct, frozen=True, tag="ready"):
    """A worker built its robots, opened them and waits for the start."""


class Go(msgspec.Struct, frozen=True, tag="go"):
    """Start: on scaled time, simulated time 0 is wall-clock instant ``epoch``."""

    epoch: float


class Window(msgspec.Struct, frozen=True, tag="window"):
    """What a worker's robots did in window ``k`` (``-1`` on scaled time), and what comes next.

    ``stopped_at``: the instant every robot of the worker had stopped (their
    ``run()`` returned), once they have; the world ends the run as *stopped* if
    the objective was not met by the latest such instant of all workers.
    ``busy``: wall seconds the worker spent on the window, from when it could run
    it (the others' windows before it in hand, and the grant) until it published
    it (see :mod:`._window_costs`).
    """

    k: int
    next_event: float
    observation: Observation
    remote: list[Remote]
    counts: Counts
    until: Annotated[float, finite(ge=0)] = 0.0
    """Virtual time: the window's end. Every event of the worker before it has run."""
    promise: Annotated[float, finite(ge=0)] = 0.0
    """Virtual time: nothing the worker does from now on reaches another before it."""
    stopped_at: Annotated[float, finite(ge=0)] | None = None
    busy: Annotated[float, finite(ge=0)] = 0.0
    cells: list[int] = msgspec.field(default_factory=list)
    """At an epoch's start, with an interaction range: robot, column, row of each of
    the worker's robots (see :mod:`._halo`)."""


class Grant(msgspec.Struct, frozen=True, tag="grant"):
    """The workers may run every window up to the end of step ``steps`` (see ``_windows.Steps``).

    The world lets the workers run a step (``run.credit``) past the one it observed
    last, and no further than the end of the run once it is decided. Where windows
    end does not depend on it: only when a worker may run them.
    """

    steps: Annotated[int, msgspec.Meta(ge=0)]


class Beat(msgspec.Struct, frozen=True, tag="beat"):
    """The world lives (every :data:`BEAT_EVERY` wall seconds, whatever else it says)."""


class Refused(msgspec.Struct, frozen=True, tag="refused"):
    """The world's answer to a hello whose tag does not check against its key.

    Signed with the world's key, which the worker's does not check either: what
    the worker learns is that the keys differ (see :func:`~._joining.join`).
    """

    reason: str


class Stop(msgspec.Struct, frozen=True, tag="stop"):
    """The run is over: stop the robots, say :class:`Bye`."""


class Failed(msgspec.Struct, frozen=True, tag="failed"):
    """A worker failed (its robots stopped), or refused the run's configuration: why."""

    error: str
    configuration: bool = False
    """True: the scenario cannot run on the worker's host (before its robots existed)."""


class Bye(msgspec.Struct, frozen=True, tag="bye"):
    """A worker stopped: its last counts, and the wall seconds it spent waiting.

    ``waited``: for the others' windows and the world's grants (virtual time),
    the part of a run across processes that is synchronisation, not simulation;
    ``waited_grant``: the part of it after the others' windows were all in, for a
    grant alone (the world was on the worker's way).
    """

    counts: Counts
    waited: float = 0.0
    waited_grant: float = 0.0
    dependencies: float = 0.0
    """With an interaction range: the workers it depended on, on average over its windows."""
    watched: float = 0.0
    """With an interaction range: the others' robots it watched, on average over its windows."""


Control = Union[  # noqa: UP007
    Hello, Welcome, Full, Refused, Ready, Go, Window, Grant, Beat, Stop, Failed, Bye
]
"""Every message of the control plane."""


class _Envelope(msgspec.Struct, frozen=True, array_like=True):
    run: str
    sender: int
    count: int
    body: bytes


_ENVELOPE: Final = msgspec.msgpack.Decoder(_Envelope)
_CONTROL: Final = msgspec.msgpack.Decoder(Control)
_ENCODE: Final = msgspec.msgpack.Encoder().encode


class Channel:
    """Sends and receives control messages of one run through a Zenoh session.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it).
        namespace: the run's key prefix (random per run: the run's id).
        sender: this process's id (:data:`WORLD`, or the worker's index).
        key: the swarm key that signs every message, or ``None``.
        handle: called on the event loop with ``(suffix, sender, message)`` for each
            message that passed every check; what it raises is counted as
            ``control.unusable`` and the batch goes on.
        refused: called on the event loop with ``(suffix, reason)`` for each message
            refused (after it is counted).
    """

    def __init__(
        self,
        session: Any,
        namespace: str,
        sender: int,
        key: SwarmKey | None,
        handle: Callable[[str, int, Control], None],
        refused: Callable[[str, str], None] = lambda suffix, reason: None,
    ) -> None:
        import zenoh

        self._session = session
        self._namespace = namespace
        self._prefix = f"{namespace}/ctl/"
        self._sender = sender
        self._secret = None if key is None else key.secret
        self._handle = handle
        self._on_refused = refused
        self._count = 0
        self._seen: dict[tuple[int, str], int] = {}  # (sender, key) -> the highest count taken
        self._inbox: ThreadInbox[tuple[str, bytes]] = ThreadInbox(
            asyncio.get_running_loop(), self._drain
        )
        self._subscribers: list[Any] = []
        self._block = zenoh.CongestionControl.BLOCK
        self.refused: dict[str, int] = {}
        """Messages refused, by reason (``control.<reason>``)."""

    def listen(self, suffix: str) -> None:
        """Receives what is published under ``{namespace}/ctl/{suffix}`` (wildcards allowed)."""
        inbox = self._inbox
        self._subscribers.append(
            self._session.declare_subscriber(
                self._prefix + suffix,
                lambda sample: inbox.put((str(sample.key_expr), sample.payload.to_bytes())),
            )
        )

    def send(self, suffix: str, message: Control) -> None:
        """Publishes ``message`` under ``{namespace}/ctl/{suffix}``, reliably."""
        key = self._prefix + suffix
        self._count += 1
        payload = _ENCODE(_Envelope(self._namespace, self._sender, self._count, _ENCODE(message)))
        if self._secret is not None:
            payload += _tag(self._secret, key, payload)
        self._session.put(key, payload, congestion_control=self._block)

    async def send_when_heard(self, suffix: str, message: Control, limit: float) -> None:
        """Sends ``message`` once someone subscribes to ``suffix`` (or ``limit`` wall s passed).

        For a session that has just connected, with one thing to say before it
        closes: a put before the subscription is known there would go nowhere.
        """
        publisher = self._session.declare_publisher(self._prefix + suffix)
        try:
            for _ in range(max(1, round(limit / _MATCHING_POLL))):
                if publisher.matching_status.matching:
                    break
                await asyncio.sleep(_MATCHING_POLL)
        finally:
            publisher.undeclare()
        self.send(suffix, message)

    def close(self) -> None:
        """Stops receiving (the session stays open); idempotent."""
        subscribers, self._subscribers = self._subscribers, []
        for subscriber in subscribers:
            with contextlib.suppress(Exception):
                subscriber.undeclare()

    def _refuse(self, key_expr: str, reason: str) -> None:
        key = f"control.{reason}"
        self.refused[key] = self.refused.get(key, 0) + 1
        self._on_refused(key_expr[len(self._prefix) :], reason)

    def _drain(self, entries: list[tuple[str, bytes]]) -> None:
        for key, payload in entries:
            if self._secret is not None:
                body, tag = payload[:-_TAG], payload[-_TAG:]
                if len(payload) < _TAG or not hmac.compare_digest(
                    tag, _tag(self._secret, key, body)
                ):
                    self._refuse(key, "unsigned")
                    continue
                payload = body
            try:
                envelope = _ENVELOPE.decode(payload)
                message = _CONTROL.decode(envelope.body)
            except (msgspec.DecodeError, RecursionError):
                self._refuse(key, "malformed")
                continue
            if envelope.run != self._namespace:
                self._refuse(key, "other_run")
                continue
            # By key: one sender's messages under one key come in the order sent, but
            # under two keys through two subscriptions (two threads), not always.
            seen = (envelope.sender, key)
            if envelope.count <= self._seen.get(seen, 0):
                self._refuse(key, "replayed")
                continue
            self._seen[seen] = envelope.count
            try:
                self._handle(key[len(self._prefix) :], envelope.sender, message)
            except Exception:
                self._refuse(key, "unusable")


def _tag(secret: bytes, key: str, payload: bytes) -> bytes:
    """The signature of ``payload`` published under ``key``."""
    return hmac.new(secret, key.encode() + b"\0" + payload, hashlib.sha256).digest()[:_TAG]


def token_lives(session: Any, key: str) -> bool:
    """Whether a liveliness token under ``key`` answers (blocking: run it in a thread).

    A token's going is a hint that its process is gone, never proof: anyone on the
    network can declare a token of any name and undeclare it. Asking whether one
    still answers tells a stranger's token going from the real one's.
    """
    try:
        return any(reply.ok is not None for reply in session.liveliness().get(key, timeout=1.0))
    except Exception:  # the session is closing, or cut off: nobody answers
        return False
