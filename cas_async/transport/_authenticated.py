"""Authenticates every datagram of a transport with a key the swarm shares (HMAC-SHA256).

Turning it on: give every robot of the swarm the same :class:`~cas_async._wire._swarm_key.SwarmKey`,
from the environment (``CAS_ASYNC_SWARM_KEY``, hex) or from a key file, never from the
scenario file, and wrap the transport::

    key = SwarmKey.from_env() or SwarmKey.from_file("/etc/cas_async/swarm.key")
    transport = AuthenticatedTransport(UdpTransport(directory, host="0.0.0.0"), key)

What it protects against, for anyone without the key: forged datagrams, altered
datagrams, datagrams replayed (recorded and sent again, to the same robot or to
another), and datagrams claiming a sender they do not come from. Among key holders a
robot cannot claim another robot's id in its message header: the robot is handed
the sender id signed in the trailer and refuses a header that differs.

What it does not protect: confidentiality (payloads travel in clear; anyone on the
path reads them), and impersonation by a key holder: the key is shared, so whoever
holds it can sign as any robot. Keep the key as secret as the swarm is trusted. Nor
can it stop a datagram from being dropped or delayed, and replay protection lives in
memory: a robot that restarts, or forgets a sender (beyond
:attr:`AuthenticatedTransport.MAX_SENDERS`), accepts once more what was recorded before.

Wire format, appended to the inner datagram (a 32-byte trailer)::

    payload || sender (8 bytes, signed big-endian robot id)
            || counter (8 bytes, unsigned big-endian) || tag (16 bytes)

``tag`` is HMAC-SHA256 truncated to 16 bytes over ``receiver || payload || sender ||
counter``, the receiver id (8 bytes, signed big-endian) being implied: a datagram for
one robot does not verify at another, so it cannot be replayed there.

Counters: each endpoint starts at the microseconds since the epoch and adds one per
datagram sent, so a robot restarted later starts above where it stopped, provided
it sent fewer than a million datagrams per second on average and its wall clock did
not step back across the restart. Each receiver keeps, per sender, the highest
counter seen and which of the :attr:`~AuthenticatedTransport.WINDOW` counters below
it arrived (a sliding window as in IPsec and DTLS): reordering within the window
is accepted, a counter seen before is a replay (``auth.replay``), one below the
window is refused as ``auth.stale``. A re-sent request is signed again with a
fresh counter, so only copies made after signing are refused.

Refusals go to the robot's ``transport_dropped`` (counted as ``transport.auth.*``):
``auth.too_short``, ``auth.forged`` (the tag does not verify: altered, or signed
with another key), ``auth.replay``, ``auth.stale``.
"""

from __future__ import annotations

import hmac
import struct
import time
from collections import Counter, OrderedDict
from collections.abc import Callable
from typing import Final, final

from .._core._dedup import DUPLICATE, STALE, WINDOW, slide
from .._core._transport_contract import DatagramSink, Endpoint, Transport
from .._errors import ConfigurationError, RobotStateError, UnknownRobotError
from .._types import RobotId
from .._wire._codec import MIN_DATAGRAM
from .._wire._presence import PresenceSeal
from .._wire._swarm_key import SwarmKey
from ._wrapping import WrappingEndpoint

__all__ = ["AuthenticatedTransport"]

_TAG_SIZE: Final = 16
_TRAILER_SIZE: Final = 8 + 8 + _TAG_SIZE
_WINDOW: Final = WINDOW  # the same sliding window as the robot's duplicate check
_MAX_SENDERS: Final = 65_536
_REFUSALS: Final = ("auth.too_short", "auth.forged", "auth.replay", "auth.stale")

_ID: Final = struct.Struct(">q")
_TRAILER: Final = struct.Struct(">qQ")  # sender, counter
_MAX_COUNTER: Final = 2**64 - 1
_MAX_CACHED_PEERS: Final = 4096


def _microseconds_since_epoch() -> int:
    # Not a time measurement (STYLE rule 9 is about those): a starting counter that
    # must grow across restarts of the process, so the wall clock, even in virtual time.
    return time.time_ns() // 1000


@final
class AuthenticatedTransport(Transport):
    """Signs what robots send through ``inner`` and refuses what does not verify.

    Args:
        inner: the transport that moves the signed datagrams; marked ``authenticated``,
            and handed a :class:`~cas_async._wire._presence.PresenceSeal` (its
            :meth:`~cas_async._core._transport_contract.Transport.require_proof`): where it learns
            robots' presence from the network, only signed presence counts.
        key: the key every robot of the swarm holds.
        counter_start: called once per opened endpoint for its first counter
            (microseconds since the epoch when omitted); for tests.
        max_senders: senders whose replay window each endpoint keeps.

    Raises:
        ConfigurationError: ``key`` is no SwarmKey, ``max_senders`` is below 1, or
            ``inner`` has robots attached already (their presence is not signed).
    """

    authenticated = True

    TRAILER_SIZE: Final = _TRAILER_SIZE
    """Bytes each datagram grows by: sender, counter, tag."""
    WINDOW: Final = _WINDOW
    """Counters below the highest one seen from a sender that may still arrive (reordered)."""
    MAX_SENDERS: Final = _MAX_SENDERS
    """Default bound on the senders whose replay window an endpoint keeps; beyond it the
    least recently heard is forgotten. Only datagrams that verify take a place, so
    forgeries cannot fill it."""
    REFUSALS: Final = _REFUSALS
    """Reasons a datagram is refused, as passed to ``transport_dropped``."""

    def __init__(
        self,
        inner: Transport,
        key: SwarmKey,
        *,
        counter_start: Callable[[], int] | None = None,
        max_senders: int = _MAX_SENDERS,
    ) -> None:
        if not isinstance(key, SwarmKey):
            raise ConfigurationError(
                f"AuthenticatedTransport needs a SwarmKey, got {type(key).__name__}"
            )
        if max_senders < 1:
            raise ConfigurationError(f"max_senders must be at least 1, got {max_senders}")
        inner.require_proof(PresenceSeal(key))
        inner.authenticated = True
        self.inner = inner
        self.supports_virtual_time = inner.supports_virtual_time
        self.max_senders = max_senders
        # Keyed once: a copy per datagram skips hashing the padded key twice (~20% faster).
        self._mac = hmac.new(key.secret, digestmod="sha256")
        self._counter_start = counter_start or _microseconds_since_epoch
        self._stats: Counter[str] = Counter()

    @property
    def stats(self) -> dict[str, int]:
        """Datagrams accepted (``"accepted"``) and refused by reason, over all endpoints."""
        return {reason: self._stats[reason] for reason in ("accepted", *_REFUSALS)}

    async def open(self, robot_id: RobotId, sink: DatagramSink) -> Endpoint:
        """Opens ``inner`` for the robot, with a sink that verifies before delivering.

        Raises:
            ConfigurationError: the robot id does not fit 8 signed bytes, the first
                counter is not in 0..2**64-1, the inner datagrams are too small for
                the trailer, or ``inner.open`` refuses.
        """
        try:
            own = _ID.pack(robot_id)
        except struct.error:
            raise ConfigurationError(
                f"robot {robot_id!r}: an authenticated robot id must be an int in "
                f"{-(2**63)}..{2**63 - 1}"
            ) from None
        start = self._counter_start()
        if not 0 <= start <= _MAX_COUNTER:
            raise ConfigurationError(
                f"robot {robot_id}: first counter {start} is not in 0..2**64-1"
            )
        verifier = _Verifier(self, own, sink)
        inner = await self.inner.open(robot_id, verifier)
        if inner.max_datagram_size - _TRAILER_SIZE < MIN_DATAGRAM:
            inner.close()
            raise ConfigurationError(
                f"robot {robot_id}: {type(self.inner).__name__} carries {inner.max_datagram_size} "
                f"bytes; with the {_TRAILER_SIZE}-byte authentication trailer at least "
                f"{MIN_DATAGRAM + _TRAILER_SIZE} are needed"
            )
        return _AuthenticatedEndpoint(self, inner, own, start)

    def __repr__(self) -> str:
        return f"AuthenticatedTransport({self.inner!r})"


@final
class _AuthenticatedEndpoint(WrappingEndpoint):
    """Signs each datagram with a fresh counter before the inner endpoint sends it."""

    __slots__ = ("_counter", "_macs", "_network", "_own")

    def __init__(
        self, network: AuthenticatedTransport, inner: Endpoint, own: bytes, start: int
    ) -> None:
        super().__init__(inner, overhead=_TRAILER_SIZE)
        self._network = network
        self._own = own
        self._counter = start
        # Keyed MACs with the receiver id already hashed in, one per peer sent to.
        self._macs: dict[RobotId, hmac.HMAC] = {}

    def send(self, robot_id: RobotId, data: bytes) -> None:
        self._counter = counter = self._counter + 1
        mac = self._macs.get(robot_id)
        if mac is None:
            mac = self._mac_for(robot_id)
        mac = mac.copy()
        try:
            head = data + self._own + counter.to_bytes(8, "big")
        except OverflowError:
            raise RobotStateError(
                f"robot {self.robot_id}: the authentication counter is exhausted; "
                "restart the robot with a smaller counter_start"
            ) from None
        mac.update(head)
        self._inner.send(robot_id, head + mac.digest()[:_TAG_SIZE])

    def _mac_for(self, robot_id: RobotId) -> hmac.HMAC:
        try:
            receiver = _ID.pack(robot_id)
        except struct.error:
            raise UnknownRobotError(
                f"robot {self.robot_id}: robot {robot_id!r} cannot be in an authenticated "
                "swarm (ids are 8-byte signed ints)"
            ) from None
        if len(self._macs) >= _MAX_CACHED_PEERS:  # bounded even if layers name many ids
            self._macs.clear()
        mac = self._macs[robot_id] = self._network._mac.copy()
        mac.update(receiver)
        return mac


@final
class _Verifier:
    """The inner endpoint's sink: verifies, checks the replay window, then delivers."""

    __slots__ = ("_mac", "_max_senders", "_sink", "_stats", "_windows")

    def __init__(self, network: AuthenticatedTransport, own: bytes, sink: DatagramSink) -> None:
        self._sink = sink
        self._stats = network._stats
        self._max_senders = network.max_senders
        self._mac = network._mac.copy()
        self._mac.update(own)  # only datagrams addressed to this robot verify here
        # sender -> (highest counter, bit i set when counter highest - i arrived),
        # least recently heard first.
        self._windows: OrderedDict[RobotId, tuple[int, int]] = OrderedDict()

    def datagram_received(self, data: bytes, sender: RobotId | None = None) -> None:
        # ``sender`` (the inner transport's guess from the source address) is not
        # needed: the trailer names the sender, and the tag proves it.
        size = len(data)
        if size < _TRAILER_SIZE:
            self._refuse(
                "auth.too_short",
                f"{size} bytes, shorter than the {_TRAILER_SIZE}-byte authentication trailer",
            )
            return
        mac = self._mac.copy()
        mac.update(memoryview(data)[: size - _TAG_SIZE])
        if not hmac.compare_digest(mac.digest()[:_TAG_SIZE], data[size - _TAG_SIZE :]):
            source = "" if sender is None else f" from the address of robot {sender}"
            self._refuse(
                "auth.forged",
                f"datagram of {size} bytes{source} does not verify: altered, or signed "
                "with another swarm key",
            )
            return
        # Only now, the tag verified, may the datagram touch the window.
        signer, counter = _TRAILER.unpack_from(data, size - _TRAILER_SIZE)
        refusal = self._admit(signer, counter)
        if refusal is not None:
            self._refuse(*refusal)
            return
        self._stats["accepted"] += 1
        self._sink.datagram_received(data[: size - _TRAILER_SIZE], signer)

    def _admit(self, signer: RobotId, counter: int) -> tuple[str, str] | None:
        """Records ``counter`` from ``signer``; the refusal if it was seen or is too old."""
        windows = self._windows
        window = windows.get(signer)
        if window is None:
            if len(windows) >= self._max_senders:
                windows.popitem(last=False)
            windows[signer] = (counter, 1)
            return None
        top, mask = window
        verdict, highest, mask = slide(top, mask, counter)
        if verdict == STALE:
            return (
                "auth.stale",
                f"robot {signer}: counter {counter} is {top - counter} behind the newest "
                f"({top}), beyond the replay window of {_WINDOW}",
            )
        if verdict == DUPLICATE:
            return ("auth.replay", f"robot {signer}: counter {counter} was already accepted")
        windows[signer] = (highest, mask)
        windows.move_to_end(signer)
        return None

    def _refuse(self, reason: str, detail: str) -> None:
        self._stats[reason] += 1
        self._sink.transport_dropped(reason, detail)

    def transport_dropped(self, reason: str, detail: str) -> None:
        self._sink.transport_dropped(reason, detail)

    def robot_joined(self, robot_id: RobotId) -> None:
        self._sink.robot_joined(robot_id)

    def robot_left(self, robot_id: RobotId) -> None:
        self._sink.robot_left(robot_id)
