"""Back-pressure between the layers of a robot: who filled whose inbox, who waits on whom.

Internal messages are never dropped: a send that fills another layer's inbox (see
:mod:`cas_async._core._channel`) marks the sender *congested*, and after the hook that
sent it, the sender waits until that inbox has drained to half its limit.

A layer never waits on one that waits, along a chain, on it: two layers flooding
each other, or a consumer asking its producer, would wait forever. One of them
goes on instead, which drains the other's sender. A layer waits on another while
it waits for room in its inbox, or for its answer to a request (then it handles
nothing either); a layer that starts waiting on one held back by it releases it,
so the check is made again.
"""

from __future__ import annotations

from typing import Any, final

from ._channel import Channel

__all__ = ["Flow"]


@final
class Flow:
    """One layer's part in back-pressure.

    Args:
        inbox: the layer's inbox (others wait for room in it).
    """

    __slots__ = ("_inbox", "_waiting_on", "congested")

    def __init__(self, inbox: Channel[Any]) -> None:
        self._inbox = inbox
        # The layers this one waits on, once per wait: a layer may wait on several at
        # once (requests to two layers gathered), and on one twice.
        self._waiting_on: list[Flow] = []
        self.congested: Flow | None = None
        """The layer whose inbox this one filled since it last waited for room.

        Read after every hook (``is not None``: a plain attribute, no call); set
        through :meth:`filled`."""

    def filled(self, other: Flow) -> None:
        """This layer's send filled ``other``'s inbox: it waits after its hook."""
        self.congested = other

    async def wait_for_room(self) -> None:
        """Waits while the layer this one filled drains to half its limit (see the module docs)."""
        target = self.congested
        self.congested = None
        if target is None:
            return
        while target._inbox.crowded and not target.waits_on(self):
            self._waiting_on.append(target)
            try:
                await target._inbox.room()
            finally:
                self._waiting_on.remove(target)

    def waits_on(self, other: Flow) -> bool:
        """Whether this layer waits, directly or along a chain, on ``other``."""
        seen: set[int] = set()
        along = [self]
        while along:
            flow = along.pop()
            if flow is other:
                return True
            if id(flow) not in seen:
                seen.add(id(flow))
                along.extend(flow._waiting_on)
        return False

    def asking(self, other: Flow) -> None:
        """This layer waits for ``other``'s answer to a request (until :meth:`answered`).

        While it waits it handles nothing, so a layer waiting for room in this
        layer's inbox must not wait on it: those are released to look again.
        """
        self._waiting_on.append(other)
        self._inbox.release_room_waiters()

    def answered(self, other: Flow) -> None:
        """This layer's request to ``other`` is over (answered, timed out or cancelled)."""
        self._waiting_on.remove(other)
