"""How early an event loop may run a timer, so that none goes off before its instant (internal).

The stdlib loop runs the timers due within its clock resolution (a nanosecond);
uvloop rounds delays to whole milliseconds, and runs one of under half a
millisecond at once. A timer armed for ``when + timer_pad(loop)`` never runs
before ``loop.time() >= when``: what the clock and the deliveries rely on, so that
nothing a robot sees at an instant happens before its clock has reached it.
"""

from __future__ import annotations

import asyncio
import time
from typing import Final

__all__ = ["timer_pad"]

_MILLISECOND_ROUNDING: Final = 0.0005 + 1e-6
"""Loop seconds a millisecond-rounding loop (uvloop) may run a timer early, and a hair."""

_NANOSECOND: Final = time.get_clock_info("monotonic").resolution
"""The stdlib loop's clock resolution: the least pad, also on a loop that reports less.

The virtual-time loop runs a timer at its instant exactly (its resolution is the
spacing of floats); a scaled clock on it still needs a pad, for the rounding of
its conversion between loop and simulated time."""


def timer_pad(loop: asyncio.AbstractEventLoop) -> float:
    """Loop seconds to add to a deadline so that a timer armed for it never goes off early."""
    if type(loop).__module__.partition(".")[0] == "uvloop":
        return _MILLISECOND_ROUNDING
    resolution = getattr(loop, "_clock_resolution", 0.0)
    return max(float(resolution) if isinstance(resolution, int | float) else 0.0, _NANOSECOND)
