"""Duplicate suppression for external messages, and the replies kept for re-sent requests.

Networks duplicate datagrams, and a requester that got no answer sends its request
again (``request(..., retries=n)`` re-sends the same message, same ``msg_id``).
Either way a message must not be handled twice. A robot's message ids only grow
(they start from the clock's :meth:`~cas_async._time._clock.Clock.message_id_base`, so a
restarted robot continues above its previous life), which allows the sliding
window of IPsec and DTLS anti-replay: per sender, the highest id seen and a
bitmask of the :data:`WINDOW` ids below it. Memory is constant per sender, and
delivery out of order within the window is fine. An id older than the window
cannot be judged and is refused as stale.

Ids count from the sender's clock (microseconds), so an id far beyond the
receiver's own clock cannot be honest: one such id, if believed, would make all of
the sender's real messages look old. A jump ahead (or a sender's first id) is
therefore checked against a *horizon*, the receiver's clock plus a slack that
covers clock skew between hosts and bursts faster than a message per
microsecond; an id beyond it is refused (:data:`FUTURE`) and moves nothing.

A request handled once but re-sent (its reply was lost) must get the same reply
again without being handled again: :class:`ReplyCache` keeps the encoded replies
of the requests answered within the last ``keep_for`` seconds (longer than any
asker's retries last), within a byte budget, and the robot sends the kept bytes
back.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

from .._types import RobotId

__all__ = [
    "DUPLICATE",
    "FRESH",
    "FUTURE",
    "ID_SLACK",
    "STALE",
    "WINDOW",
    "ReplyCache",
    "SenderWindows",
    "slide",
]

WINDOW: Final = 1024
"""Message ids per sender below its highest that are still told apart."""

FRESH: Final = 0
"""First sight of this message: handle it."""
DUPLICATE: Final = 1
"""Seen before: a network duplicate or a re-sent request."""
STALE: Final = 2
"""Older than the window: cannot tell, so refused."""
FUTURE: Final = 3
"""Beyond the horizon: no honest sender can have used it yet, so refused."""

ID_SLACK: Final = 2**32
"""Ids a sender may be ahead of the receiver's clock: about 71 minutes of clock
skew (ids are microseconds), or four billion messages in one virtual instant."""

_MASK: Final = (1 << WINDOW) - 1


def slide(highest: int, mask: int, n: int) -> tuple[int, int, int]:
    """One step of the anti-replay window: ``(verdict, highest, mask)`` after seeing ``n``.

    ``highest`` is the largest number seen, and bit ``k`` of ``mask`` is set when
    ``highest - k`` was seen. The verdict is FRESH, DUPLICATE or STALE; a number
    that is not FRESH leaves the window as it was.
    """
    ahead = n - highest
    if ahead > 0:
        # A jump of a whole window or more (a restarted sender) starts afresh:
        # shifting by it would build an enormous integer.
        return FRESH, n, ((mask << ahead) | 1) & _MASK if ahead < WINDOW else 1
    if ahead <= -WINDOW:
        return STALE, highest, mask
    bit = 1 << -ahead
    if mask & bit:
        return DUPLICATE, highest, mask
    return FRESH, highest, mask | bit


def _unbounded() -> int:
    return 2**64  # beyond any 64-bit message id


class _Window:
    __slots__ = ("heard", "highest", "mask")

    def __init__(self, msg_id: int, heard: float) -> None:
        self.highest = msg_id
        self.mask = 1  # bit k: id ``highest - k`` seen
        self.heard = heard


class SenderWindows:
    """Which message ids each sender has had delivered, and when it was last heard.

    Args:
        max_senders: senders tracked at most; beyond it the one tracked longest is
            forgotten (its next message is taken as new), so claimed sender ids
            cannot grow memory without bound.
    """

    __slots__ = ("_max_senders", "_windows")

    def __init__(self, max_senders: int = 65_536) -> None:
        self._windows: dict[RobotId, _Window] = {}
        self._max_senders = max_senders

    def check(
        self, sender: RobotId, msg_id: int, now: float, horizon: Callable[[], int] = _unbounded
    ) -> int:
        """Records ``msg_id`` from ``sender`` heard at ``now``: FRESH, DUPLICATE, STALE or FUTURE.

        ``horizon()`` gives the largest id an honest sender can have used (no limit
        when omitted); it is asked only for a sender's first id and for jumps of a
        window or more. A FUTURE id changes nothing, not even when the sender was
        last heard.
        """
        window = self._windows.get(sender)
        if window is None:
            if msg_id > horizon():
                return FUTURE
            windows = self._windows
            if len(windows) >= self._max_senders:
                del windows[next(iter(windows))]
            windows[sender] = _Window(msg_id, now)
            return FRESH
        ahead = msg_id - window.highest
        if 0 < ahead < WINDOW:  # newer than all before it: slide()'s common case, inlined
            window.heard = now
            window.highest = msg_id
            window.mask = ((window.mask << ahead) | 1) & _MASK
            return FRESH
        if ahead > 0 and msg_id > horizon():
            return FUTURE
        window.heard = now
        verdict, window.highest, window.mask = slide(window.highest, window.mask, msg_id)
        return verdict

    def forget(self, sender: RobotId, msg_id: int) -> None:
        """Unmarks ``msg_id`` from ``sender`` (it was not delivered after all)."""
        window = self._windows.get(sender)
        if window is not None and 0 <= window.highest - msg_id < WINDOW:
            window.mask &= ~(1 << (window.highest - msg_id))

    def heard(self, sender: RobotId) -> float | None:
        """When ``sender`` was last heard (the ``now`` of its latest message), or ``None``."""
        window = self._windows.get(sender)
        return None if window is None else window.heard

    def __len__(self) -> int:
        return len(self._windows)


def _cost(data: bytes) -> int:
    """Bytes a kept reply counts against the budget.

    Robots that pass message objects (``MemoryTransport(pass_objects=True)``) keep
    the object itself: its size is not known, only the overhead counts.
    """
    return (len(data) if type(data) is bytes else 0) + ReplyCache.OVERHEAD


class ReplyCache:
    """The encoded replies to the requests answered lately, kept by age within a budget.

    A reply is kept at least ``keep_for`` seconds (of whatever clock gives ``now``):
    an asker that lost it re-sends its request within its retries, and however many
    other requests it asked meanwhile, the reply is still there. The byte budget
    bounds memory whatever the traffic.

    Replies are kept in two generations: the current one, and the one before. When
    a reply is kept and the current generation is ``keep_for`` old, or would hold
    more than half the budget, it becomes the one before, and the one before is
    dropped whole. So replies go only as later ones are kept (a robot that stops
    answering keeps its last ones, within the budget), keeping a reply is one
    dictionary insertion (a robot keeps every reply it sends), and forgetting costs
    nothing per reply. When the budget is what runs out, the older half goes at
    once. With ``keep_for`` 0 the last reply or two stay; with a budget too small
    for any reply, the last one.

    Args:
        keep_for: how long a reply is kept, at least.
        budget: most bytes kept (replies plus a fixed overhead per reply), about.
    """

    __slots__ = ("_before", "_before_bytes", "_bytes", "_current", "_half", "_keep_for", "_since")

    OVERHEAD: Final = 200
    """Bytes a kept reply costs besides its own (key, entry, dictionary slot), roughly."""

    def __init__(self, keep_for: float = 60.0, budget: int = 1 << 20) -> None:
        self._current: dict[tuple[RobotId, int], bytes] = {}
        self._before: dict[tuple[RobotId, int], bytes] = {}
        self._bytes = self._before_bytes = 0
        self._since: float | None = None  # when the current generation began
        self._keep_for = keep_for
        self._half = budget // 2

    def keep(self, asker: RobotId, request_id: int, data: bytes, now: float) -> None:
        """Remembers ``data`` as the reply sent at ``now`` to ``asker``'s request ``request_id``."""
        # _cost(data), inline: this runs for every reply a robot sends
        cost = (len(data) if data.__class__ is bytes else 0) + ReplyCache.OVERHEAD
        since = self._since
        if since is None or now - since >= self._keep_for or self._bytes + cost > self._half:
            self._before, self._before_bytes = self._current, self._bytes
            self._current, self._bytes, self._since = {}, 0, now
        current = self._current
        key = (asker, request_id)
        old = current.get(key)
        if old is not None:  # kept again: counted once
            self._bytes -= _cost(old)
        current[key] = data
        self._bytes += cost

    def get(self, asker: RobotId, request_id: int) -> bytes | None:
        """The reply sent to that request, if still kept."""
        key = (asker, request_id)
        data = self._current.get(key)
        return data if data is not None else self._before.get(key)

    @property
    def size(self) -> int:
        """Bytes counted against the budget now."""
        return self._bytes + self._before_bytes

    def __len__(self) -> int:
        return len(self._current) + len(self._before)
