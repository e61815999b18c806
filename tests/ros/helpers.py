"""Shared pieces of the ROS tests: free ports, a plain Zenoh router, bounded polling."""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import AsyncIterator, Callable
from typing import Any


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
