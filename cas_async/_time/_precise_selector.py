"""An epoll selector whose timeouts are exact to the microsecond, not to the millisecond.

``epoll_wait`` takes whole milliseconds, so the stdlib selector rounds every
timeout up: a timer due in 0.3 ms fires after 1 ms, and on average half a
millisecond late. Under a :class:`~cas_async.ScaledClock` that lateness is
multiplied by the time factor (at factor 100, 50 ms of simulated time per timer),
and it adds up along a chain of timed actions.

``select()`` takes microseconds, and an epoll descriptor can itself be watched:
it is readable when any descriptor it holds is ready. So a wait first sleeps the
whole milliseconds in ``epoll_wait`` (where a datagram arriving meanwhile wakes it
with one system call, as before), then the rest in ``select()`` on the epoll
descriptor. :func:`cas_async.loop_factory` gives the stdlib loop this selector.
"""

from __future__ import annotations

import math
import select
import selectors
import sys
import time

__all__ = ["precise_selector_available"]


def precise_selector_available() -> bool:
    """True where epoll exists (Linux): elsewhere the stdlib selector is kept."""
    return sys.platform == "linux"


# Defined on Linux only: elsewhere selectors has no EpollSelector to build on (and
# kqueue, on macOS, already takes timeouts in nanoseconds).
if sys.platform == "linux":

    class PreciseEpollSelector(selectors.EpollSelector):
        """:class:`selectors.EpollSelector`, but a timeout is waited out to the microsecond.

        ``select.select`` cannot watch a descriptor numbered 1024 or more: if the epoll
        descriptor is one (a process that opened that many files before creating its
        loop), the selector falls back to millisecond timeouts for good.
        """

        def __init__(self) -> None:
            super().__init__()
            self._precise = True

        def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
            """Waits up to ``timeout`` seconds (``None``: for ever) for a registered descriptor."""
            if timeout is None or timeout <= 0 or not self._precise:
                return super().select(timeout)
            whole_ms = math.floor(timeout * 1e3)
            if whole_ms > 0:
                deadline = time.monotonic() + timeout
                # A hair under: the stdlib rounds up, and 7 * 1e-3 * 1e3 is 7.000000000000001.
                ready = super().select(whole_ms * 1e-3 - 1e-7)
                if ready:
                    return ready
                timeout = deadline - time.monotonic()
                if timeout <= 0:
                    return ready
            try:
                select.select([self.fileno()], [], [], timeout)
            except ValueError:  # descriptor out of select()'s range
                self._precise = False
                return super().select(timeout)
            return super().select(0)

    __all__ += ["PreciseEpollSelector"]
