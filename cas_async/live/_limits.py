"""What a view's server allows a client (:class:`ServerLimits`), as production servers do.

A page, a replay's scrubber or a script is answered in milliseconds; what holds a
connection longer than these limits is a client that went away without closing, or
a stranger keeping a door open. Every limit is in wall seconds, whatever the loop's
clock: the server's sweeps run from a thread (see
:class:`~cas_async.live._pacer.WallTicker`), so a run on virtual time has them too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

__all__ = ["BUSY_LINGER", "ServerLimits"]

BUSY_LINGER: Final = 1.0
"""Wall seconds a connection turned away (503) may take to close its side."""


@dataclass(frozen=True, slots=True)
class ServerLimits:
    """The limits of a view's server (:class:`~cas_async.live.LiveView`, ``ReplayView``).

    Attributes:
        request_timeout: wall seconds a client has to send its whole request head
            (else ``408 Request Timeout``), and to read an answer or a close frame
            before the connection is cut.
        idle_timeout: wall seconds a viewer may send nothing, not even the pong that
            answers the server's ping (sent after half of it), before it is closed
            (``1001 going away``): a browser answers pings by itself, a viewer that
            stopped reading does not.
        max_connections: connections served at once; one more is answered
            ``503 Service Unavailable`` and counted (``refused["busy"]``).
        tick: wall seconds between two sweeps of the connections, and the back-off
            of accepting when the process is out of file descriptors.

    Raises:
        ValueError: a limit is not a positive number (``max_connections`` an int >= 1).
    """

    request_timeout: float = 10.0
    idle_timeout: float = 20.0
    max_connections: int = 512
    tick: float = 1.0

    def __post_init__(self) -> None:
        for name in ("request_timeout", "idle_timeout", "tick"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"ServerLimits: {name} must be a number of seconds, got {value!r}")
            if not 0 < value < math.inf:
                raise ValueError(f"ServerLimits: {name} must be > 0 s, got {value!r}")
        count = self.max_connections
        if isinstance(count, bool) or not isinstance(count, int) or count < 1:
            raise ValueError(f"ServerLimits: max_connections must be an int >= 1, got {count!r}")

    @property
    def ping_every(self) -> float:
        """Wall seconds of a viewer's silence after which the server pings it."""
        return self.idle_timeout / 2
