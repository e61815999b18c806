"""Shared pieces of the ROS tests: free ports, a plain Zenoh router, bounded polling, time-outs."""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import AsyncIterator, Callable
from typing import Any, Final

PATIENT: Final = {"discovery_timeout": 120.0, "odom_timeout": 40.0}
"""RosDiffDrive's time-outs for a loaded machine, in simulated seconds (a quarter in wall time).

RosDiffDrive's defaults (10 s to find the robot, 1 s without odometry) are simulated
seconds: at the tests' time factor of 4 a quarter of a wall second without odometry would
fail a move. The first odometry after the topics are found takes some 50 ms of wall
time on an idle 2-core machine, some 100-130 ms beside one CPU hog and up to 275 ms at
a load of 5 (measured), so a test that is not about time-outs waits longer than any
of that; a test of a time-out passes its own.
"""


def free_port() -> int:
    """A TCP port on 127.0.0.1 nobody listens on now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


async def until(condition: Callable[[], bool], what: str, timeout: float = 10.0) -> None:
    """Waits (polling: samples travel through Zenoh's threads) until ``condition()``."""
    try:
        async with asyncio.timeout(timeout):
            while not condition():
                await asyncio.sleep(0.01)
    except TimeoutError:
        raise AssertionError(f"not within {timeout:g} s: {what}") from None


@contextlib.asynccontextmanager
async def zenoh_session(mode: str, endpoint: str) -> AsyncIterator[Any]:
    """A raw Zenoh session: a router listening on ``endpoint``, or a client of it; closed after."""
    import zenoh

    from cas_async.transport.zenoh._transport import loopback_config

    if mode == "router":
        config = loopback_config(mode="router", listen=[endpoint])
    else:
        config = loopback_config(mode="client", listen=[], connect=[endpoint])
    session = await asyncio.to_thread(zenoh.open, config)
    try:
        yield session
    finally:
        session.close()
