"""Robots on Eclipse Zenoh: discovery by liveliness tokens, reliable delivery, any process or host.

Needs the ``zenoh`` extra (``pip install "cas_async[zenoh]"``); importing this module
does not, opening the first robot does.

One Zenoh session per transport, so per process: every robot of the process shares
it. Keys, under the transport's ``namespace``::

    {namespace}/alive/{robot}/{zid}[/{stamp}/{proof}]   a robot's liveliness token
    {namespace}/d/{zid}/{receiver}/{sender}             a datagram for ``receiver``

``zid`` is the Zenoh id of the session the robot lives in. A process declares one
subscriber for the datagrams of its own session (``{namespace}/d/{zid}/*/*``) and one
for the tokens: Zenoh runs every plain callback subscriber on its own OS thread, so
one per robot would cost a thousand threads for a thousand robots. The tokens'
callback runs on Zenoh's network thread instead (``indirect=False``): a token is then
queued before any datagram its robot sent after declaring it, which would otherwise
race it through the datagrams' thread and arrive from nobody. Callbacks only
append to a queue and wake the event loop once per batch
(:class:`~cas_async.transport.zenoh._thread_inbox.ThreadInbox`); the loop then hands each
datagram to its robot, reading the pair of robots from its key once per key. Both
sides declare the keys of the pairs that talk to Zenoh, up to a budget: a publisher
per pair to send, the key expression to receive (without it, matching the wildcard
costs Zenoh's network thread 3-4 µs a sample); see :mod:`~cas_async.transport.zenoh._keys`.

Membership: a robot's token appears when it opens its endpoint and disappears when it
closes, when its process dies (about 2 ms after SIGKILL on loopback) or, for a frozen
process, when Zenoh's lease expires (about 10 s). Robots that follow membership hear
``robot_joined``/``robot_left`` (``Layer.knows``, ``on_robot_left``). A token never
moves or removes a robot already placed: a second one for it, from another session, is
refused and counted (``token_conflict``), and only the going of the token the robot is
placed by removes it (:mod:`~cas_async.transport.zenoh._members` has the rules).

The sender of a datagram is the robot named in the key it was published under, and
only while that robot's token is alive (and for :data:`LAST_WORDS` seconds after it
went: a robot's last datagrams may arrive after its token's end, as they come through
another subscriber); a datagram from a robot no token speaks for is refused as
``unknown_source``, one whose header claims another robot than its key as
``spoofed_sender``.

Zenoh lets any session that reaches this one declare tokens and publish under any key:
what a stranger can still do, without a swarm key and with one (tokens are then
signed), is in :mod:`~cas_async.transport.zenoh._members`. Refusals are counted in
:attr:`~ZenohTransport.dropped` and in a robot's drops (``transport.<reason>``).

Delivery is reliable: puts use ``CongestionControl.BLOCK``, so a full queue makes
the sender wait instead of dropping (Zenoh's default, ``DROP``, lost 22% of a burst
in one process). Datagrams between robots of the same process do not go through Zenoh:
they take the same queue as the others, so they arrive on the loop's next pass, in order.

Network defaults are loopback only: the session listens on ``tcp/127.0.0.1`` (a port
the OS picks) and multicast scouting is off, so nothing leaves this machine unless
``listen``, ``connect`` or ``config`` say so. Listening beyond loopback without a swarm
key warns (:class:`~cas_async.transport._udp.InsecureBindWarning`). Processes find
each other through ``connect`` (an endpoint another session listens on) or a router
(a session in ``mode="router"``, e.g. ``python -m cas_async world``): since Zenoh 1.9
peers do not route for other peers.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import threading
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, Final, final

from ..._core._transport_contract import DatagramSink, Endpoint, Transport
from ..._errors import ConfigurationError, RobotStateError, UnknownRobotError
from ..._types import RobotId
from ..._wire._codec import DEFAULT_MAX_DATAGRAM
from ..._wire._presence import PresenceSeal
from ._endpoint import ZenohEndpoint
from ._keys import (
    APPEARED,
    LOCAL,
    REMOTE,
    Entry,
    Publishers,
    ReceivedKeys,
    pair_of,
    subscribe,
)
from ._members import Members
from ._sessions import LOOPBACK_LISTEN, Mode, import_zenoh, loopback_config, warn_if_exposed
from ._thread_inbox import ThreadInbox

if TYPE_CHECKING:
    import zenoh

__all__ = ["ZenohTransport"]

_NAMESPACE: Final = re.compile(r"[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*")
LAST_WORDS: Final = 2.0
"""Seconds (of the loop's clock) a robot's datagrams still speak for it after its token went."""


@final
class ZenohTransport(Transport):
    """Robots in any process or host, over Eclipse Zenoh.

    Args:
        namespace: the swarm's key prefix; only robots under the same namespace
            see each other (``/``-separated words of letters, digits, ``_``, ``-``).
        mode: Zenoh's ``"peer"`` (default), ``"client"`` (everything through a
            router) or ``"router"`` (routes for others: one per swarm of many processes).
        listen: endpoints the session listens on; loopback, port picked by the OS,
            by default.
        connect: endpoints of other sessions (a router, a peer) to connect to.
        config: a complete ``zenoh.Config`` instead of the three above (yours to
            make loopback-only, or not).
        max_datagram_size: the largest datagram a robot may send, in bytes.
        shared_virtual_time: the processes' loops share virtual time through the
            barrier of a run across processes (``run --processes``), so robots may
            use a virtual clock; never set it otherwise, as a lone virtual loop would
            jump past datagrams still on their way.

    Raises:
        ConfigurationError: the namespace is not a valid key prefix.
    """

    supports_virtual_time = False

    def __init__(
        self,
        *,
        namespace: str = "cas_async",
        mode: Mode = "peer",
        listen: Sequence[str] = LOOPBACK_LISTEN,
        connect: Sequence[str] = (),
        config: zenoh.Config | None = None,
        max_datagram_size: int = DEFAULT_MAX_DATAGRAM,
        shared_virtual_time: bool = False,
    ) -> None:
        self.supports_virtual_time = shared_virtual_time
        if not isinstance(namespace, str) or not _NAMESPACE.fullmatch(namespace):
            raise ConfigurationError(
                f"Zenoh namespace must be /-separated words of letters, digits, _ and -, "
                f"got {namespace!r}"
            )
        if mode not in ("peer", "client", "router"):
            raise ConfigurationError(f"Zenoh mode must be peer, client or router, got {mode!r}")
        self.namespace = namespace
        self.mode: Mode = mode
        self.listen = tuple(listen)
        self.connect = tuple(connect)
        self._config = config
        self.max_datagram_size = max_datagram_size
        self._session: Any = None
        self._opening: asyncio.Future[Any] | None = None
        self._kept = False  # opened by start(): stays open until close()
        self._subscribers: list[Any] = []
        self._inbox: ThreadInbox[Entry] | None = None
        self._zid = ""
        self._publishers: Publishers | None = None
        self._keys: ReceivedKeys | None = None
        self._local: dict[RobotId, ZenohEndpoint] = {}
        self._members = Members(namespace, self._moved, self._refused)
        self._where = self._members.placed  # the same dict for good: read on every send
        self._followers: dict[RobotId, ZenohEndpoint] = {}
        self._waiters: list[asyncio.Future[None]] = []  # wait_for(): woken by every join
        # Robots whose token went, and when (loop time): their last datagrams may come
        # after the token's DELETE (two subscribers, no order between them) and still
        # speak for them for a moment.
        self._departed: dict[RobotId, float] = {}
        self._lock = threading.Lock()  # the session's life vs. a thread opening it
        self.sent = 0
        """Datagrams published to other processes."""
        self.received = 0
        """Datagrams from other processes handed to a robot of this one."""
        self.dropped: dict[str, int] = {}
        """What arrived and could not be handed to a robot, and tokens refused, by reason."""

    # -- the session -----------------------------------------------------------------

    @property
    def zid(self) -> str:
        """The Zenoh id of this transport's session (``""`` before the first robot opens)."""
        return self._zid

    @property
    def session(self) -> Any:
        """The open ``zenoh.Session``, or ``None``: shared with the runtime's own keys."""
        return self._session

    async def start(self) -> None:
        """Opens the session now, until :meth:`close` (else the robots open and close it).

        Without it, the first robot's ``open`` opens the session and the last
        robot's ``close`` closes it. After it, the session stays open for other
        uses (the runtime's control messages) until :meth:`close`.

        Raises:
            ConfigurationError: zenoh is missing, or the session cannot open
                (e.g. an endpoint is taken or cannot be reached).
        """
        self._kept = True
        await self._start()

    async def _start(self) -> None:
        if self._session is not None:
            return
        if self._opening is None:
            self._opening = asyncio.ensure_future(self._open_session())
        try:
            await asyncio.shield(self._opening)
        except asyncio.CancelledError:
            # The thread opening the session cannot be cancelled: let it finish and
            # close what it opened, so no session keeps the process alive.
            if self._opening is not None and not self._opening.done():
                with contextlib.suppress(Exception, asyncio.CancelledError):
                    await self._opening
            if not self._local:
                self.close()
            raise
        finally:
            if self._opening is not None and self._opening.done():
                self._opening = None

    async def _open_session(self) -> None:
        zenoh = import_zenoh()
        config = self._config
        if config is None:
            config = loopback_config(mode=self.mode, listen=self.listen, connect=self.connect)
        if not self.authenticated and self._config is None:
            warn_if_exposed(self.listen)
        try:
            session = await asyncio.to_thread(zenoh.open, config)
        except Exception as exc:  # zenoh.ZError
            raise ConfigurationError(f"cannot open a Zenoh session: {exc}") from exc
        loop = asyncio.get_running_loop()
        with self._lock:
            self._session = session
            self._zid = self._members.zid = str(session.zid())
            self._inbox = inbox = ThreadInbox(loop, self._drain)
            self._publishers = Publishers(zenoh, session, self.namespace)
            self._keys = ReceivedKeys(session)
            try:
                subscribe(zenoh, session, self.namespace, self._zid, inbox.put, self._subscribers)
            except BaseException:
                self._close_session()
                raise

    def close(self) -> None:
        """Closes every endpoint and the session; idempotent (a later ``open`` starts again)."""
        self._kept = False
        for endpoint in list(self._local.values()):
            endpoint.close()
        self._close_session()

    def _close_session(self) -> None:
        with self._lock:
            session, self._session = self._session, None
            subscribers, self._subscribers = self._subscribers, []
            self._publishers = self._keys = None  # closing the session undeclares their keys
            self._members.clear()
            self._zid = ""
        for subscriber in subscribers:
            with contextlib.suppress(Exception):
                subscriber.undeclare()
        if session is not None:
            session.close()

    async def __aenter__(self) -> ZenohTransport:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    # -- robots ----------------------------------------------------------------------

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        """Attaches a robot and declares its liveliness token.

        Raises:
            ConfigurationError: the id is not an int, is taken in this process or (without
                a swarm key) by a live robot elsewhere, or the session cannot open. With
                a key the robot opens anyway: its token, newer, places it here (the
                robot restarted; a stranger's copy of its old token must not keep it out).
        """
        if not isinstance(robot_id, int) or isinstance(robot_id, bool):
            raise ConfigurationError(f"a Zenoh robot id must be an int, got {robot_id!r}")
        if robot_id in self._local:
            raise ConfigurationError(f"robot {robot_id} is already attached to this ZenohTransport")
        await self._start()
        elsewhere = self._where.get(robot_id)
        if elsewhere is not None and elsewhere != self._zid and not self._members.sealed:
            if not self._local and not self._kept:
                self._close_session()  # opened for this robot: it must not keep the process
            raise ConfigurationError(
                f"robot {robot_id} is already on the Zenoh swarm {self.namespace!r} "
                f"(session {elsewhere})"
            )
        key = self._members.attach(robot_id)
        try:
            token = self._session.liveliness().declare_token(key)
        except BaseException:
            self._members.detach(robot_id)
            raise
        endpoint = self._local[robot_id] = ZenohEndpoint(self, robot_id, sink, token)
        return endpoint

    def detach(self, endpoint: ZenohEndpoint, token: Any) -> None:
        """Called by a closing endpoint: its token goes, the others hear it left."""
        robot_id = endpoint.robot_id
        self.follow(endpoint, False)
        if self._local.get(robot_id) is endpoint:
            del self._local[robot_id]
            if self._publishers is not None:
                self._publishers.forget_sender(robot_id)  # _moved() forgets the rest
            with contextlib.suppress(Exception):  # the session may be closed already
                token.undeclare()
            self._members.detach(robot_id)
        if not self._local and not self._kept:
            self._close_session()

    def follow(self, endpoint: ZenohEndpoint, follow: bool) -> None:
        """Whether ``endpoint``'s robot hears of robots joining and leaving."""
        if follow:
            self._followers[endpoint.robot_id] = endpoint
        elif self._followers.get(endpoint.robot_id) is endpoint:
            del self._followers[endpoint.robot_id]

    def zid_of(self, robot_id: RobotId) -> str | None:
        """The session robot ``robot_id`` lives in, while its token is alive."""
        return self._where.get(robot_id)

    async def wait_for(self, robot_ids: Iterable[RobotId]) -> None:
        """Returns once every robot of ``robot_ids`` has a live token (is reachable).

        Bound it with a timeout: a robot that never comes makes it wait for ever.
        """
        missing = set(robot_ids)
        while missing - self._where.keys():
            waiter = asyncio.get_running_loop().create_future()
            self._waiters.append(waiter)
            await waiter

    def members(self) -> list[RobotId]:
        """Every robot with a live token (this process's included)."""
        return list(self._where)

    def require_proof(self, seal: PresenceSeal) -> None:
        """Signs this process's tokens with ``seal``, and believes only tokens it verifies.

        Called by :class:`~cas_async.transport._authenticated.AuthenticatedTransport`
        when it wraps this transport; tokens heard already are judged again.

        Raises:
            ConfigurationError: robots are attached already (their tokens are unsigned).
        """
        if self._local:
            raise ConfigurationError(
                f"wrap the ZenohTransport in AuthenticatedTransport before opening robots: "
                f"robots {sorted(self._local)} have unsigned tokens already"
            )
        self._members.require(seal)

    def is_local(self, robot_id: RobotId) -> bool:
        """Whether robot ``robot_id`` is attached to this transport (this process)."""
        return robot_id in self._local

    def send_from(self, sender: RobotId, receiver: RobotId, data: bytes) -> None:
        """Sends one datagram from robot ``sender`` (of this process) to ``receiver``.

        To another process it is published, reliably (when Zenoh's queues are full,
        this waits instead of dropping); to this one, it arrives on the loop's next pass.

        Raises:
            UnknownRobotError: no live token speaks for ``receiver``.
            RobotStateError: the session is closed.
        """
        zid = self._where.get(receiver)
        if zid is None:
            raise UnknownRobotError(
                f"robot {sender}: robot {receiver} is not on this Zenoh swarm "
                f"(no liveliness token under {self.namespace!r})"
            )
        publishers, inbox = self._publishers, self._inbox
        if publishers is None or inbox is None:
            raise RobotStateError("the Zenoh session is closed")
        if zid == self._zid:
            inbox.put((LOCAL, (receiver, sender), data))
        else:
            publishers.put_for(zid, receiver, sender)(data)
            self.sent += 1

    def declared_keys(self) -> tuple[int, int]:
        """Datagram keys the session holds declared now: ``(to send, to receive)``."""
        if self._publishers is None or self._keys is None:
            return 0, 0
        return self._publishers.declared(), self._keys.declared()

    # -- what arrives ----------------------------------------------------------------

    def _drain(self, entries: list[Entry]) -> None:
        local, where = self._local, self._where
        pairs = {} if self._keys is None else self._keys.pairs
        received = 0
        for kind, what, payload in entries:
            if kind == REMOTE:
                pair = pairs.get(what) or self._first_from(what)
                if pair is None:
                    continue
                receiver, sender = pair
                received += 1
            elif kind == LOCAL:
                receiver, sender = what
            elif kind == APPEARED:
                self._members.appeared(what)
                continue
            else:
                self._members.went(what)
                continue
            endpoint = local.get(receiver)
            if endpoint is None:
                self.dropped["no_receiver"] = self.dropped.get("no_receiver", 0) + 1
                continue
            known = sender if sender in where or self._lately_here(sender) else None
            try:
                endpoint.sink.datagram_received(payload, known)
            except Exception as exc:  # a broken sink must not lose the rest of the batch
                asyncio.get_running_loop().call_exception_handler(
                    {"message": f"robot {receiver}: sink failed", "exception": exc}
                )
        self.received += received

    def _first_from(self, key: str) -> tuple[RobotId, RobotId] | None:
        """The ``(receiver, sender)`` of a key not read yet, or ``None`` (counted).

        The key is declared to the session when it joins a robot of this process
        and a live one: what a stranger makes up takes no place.
        """
        keys = self._keys
        pair = pair_of(key) if keys is None else keys.read(key)
        if pair is None:
            self._refused("bad_key", f"datagram under {key!r}, which names no two robots", None)
        elif keys is not None and pair[0] in self._local and pair[1] in self._where:
            keys.declare(key, pair)
        return pair

    def _lately_here(self, robot_id: RobotId) -> bool:
        """Whether ``robot_id`` left less than :data:`LAST_WORDS` seconds ago."""
        left = self._departed.get(robot_id)
        if left is None:
            return False
        if asyncio.get_running_loop().time() - left <= LAST_WORDS:
            return True
        del self._departed[robot_id]
        return False

    def _moved(self, robot_id: RobotId, before: str | None, after: str | None) -> None:
        """Robot ``robot_id`` joined (``before`` is ``None``), moved, or left (``after``)."""
        if self._publishers is not None and self._keys is not None:
            self._keys.forget(robot_id)  # keys naming it are weighed for declaring again
            if before is not None:
                self._publishers.forget_receiver(robot_id)  # it moved or left
        if after is None:
            with contextlib.suppress(RuntimeError):  # no loop: the session is closing
                self._departed[robot_id] = asyncio.get_running_loop().time()
            for follower in list(self._followers.values()):
                follower.sink.robot_left(robot_id)
            return
        self._departed.pop(robot_id, None)
        waiters, self._waiters = self._waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(None)
        if before is None:
            for follower in list(self._followers.values()):
                if follower.robot_id != robot_id:
                    follower.sink.robot_joined(robot_id)

    def _refused(self, reason: str, detail: str, robot_id: RobotId | None) -> None:
        """Counts a refusal here and in a robot's drops (so in a run's results).

        The robot it names counts it if it lives here, else this process's first robot.
        """
        self.dropped[reason] = self.dropped.get(reason, 0) + 1
        endpoint = self._local.get(robot_id) if robot_id is not None else None
        if endpoint is None:
            endpoint = next(iter(self._local.values()), None)
        if endpoint is not None:
            endpoint.sink.transport_dropped(reason, detail)

    def __repr__(self) -> str:
        where = f"session {self._zid}" if self._zid else "not open"
        return (
            f"ZenohTransport(namespace={self.namespace!r}, {len(self._local)} robots here, "
            f"{len(self._where)} in the swarm, {where})"
        )
