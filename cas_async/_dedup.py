"""Duplicate suppression for external messages, and the replies kept for re-sent requests.

Networks duplicate datagrams, and a requester that got no answer sends its request
again (``request(..., retries=n)`` re-sends the same message, same ``msg_id``).
Either way a message must not be handled twice. A robot's message ids only grow
(they start from the clock's :meth:`~cas_async._clock.Clock.message_id_base`, so a
restarted robot continues above its previous life), which allows the sliding
window of IPsec and DTLS anti-replay: per sender, the highest id seen and a
bitmask of the :data:`WINDOW` ids below it. Memory is constant per sender, and
delivery out of order within the window is fine. An id older than the window
cannot be judged and is refused as stale.

A request handled once but re-sent (its reply was lost) must get the same reply
again without being handled again: :class:`ReplyCache` keeps the encoded replies
of the latest requests answered, and the robot sends the kept bytes back.
"""

from __future__ import annotations

from typing import Final

from ._types import RobotId

__all__ = ["DUPLICATE", "FRESH", "STALE", "WINDOW", "ReplyCache", "SenderWindows", "slide"]

WINDOW: Final = 1024
"""Message ids per sender below its highest that are still told apart."""

FRESH: Final = 0
"""First sight of this message: handle it."""
DUPLICATE: Final = 1
"""Seen before: a network duplicate or a re-sent request."""
STALE: Final = 2
"""Older than the window: cannot tell, so refused."""

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

    def check(self, sender: RobotId, msg_id: int, now: float) -> int:
        """Records ``msg_id`` from ``sender`` heard at ``now``: FRESH, DUPLICATE or STALE."""
        window = self._windows.get(sender)
        if window is None:
            windows = self._windows
            if len(windows) >= self._max_senders:
                del windows[next(iter(windows))]
            windows[sender] = _Window(msg_id, now)
            return FRESH
        window.heard = now
        ahead = msg_id - window.highest
        if 0 < ahead < WINDOW:  # newer than all before it: slide()'s common case, inlined
            window.highest = msg_id
            window.mask = ((window.mask << ahead) | 1) & _MASK
            return FRESH
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


class ReplyCache:
    """The encoded replies to each asker's latest requests.

    A requester re-sends only while it waits, and waits on few requests at once to
    the same robot, so a few replies per asker cover every repetition; memory then
    follows the number of askers, not the number of requests ever answered.

    Args:
        per_asker: replies kept per asker; its oldest goes first.
        askers: askers kept; the one first seen goes first.
    """

    __slots__ = ("_askers", "_per_asker", "_replies")

    def __init__(self, per_asker: int = 16, askers: int = 1024) -> None:
        self._replies: dict[RobotId, dict[int, bytes]] = {}
        self._per_asker = per_asker
        self._askers = askers

    def keep(self, asker: RobotId, request_id: int, data: bytes) -> None:
        """Remembers ``data`` as the reply sent to ``asker``'s request ``request_id``."""
        replies = self._replies
        kept = replies.get(asker)
        if kept is None:
            if len(replies) >= self._askers:
                del replies[next(iter(replies))]
            kept = replies[asker] = {}
        kept[request_id] = data
        if len(kept) > self._per_asker:
            del kept[next(iter(kept))]

    def get(self, asker: RobotId, request_id: int) -> bytes | None:
        """The reply sent to that request, if still kept."""
        kept = self._replies.get(asker)
        return None if kept is None else kept.get(request_id)

    def __len__(self) -> int:
        return sum(len(kept) for kept in self._replies.values())
