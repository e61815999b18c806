"""The workers a world starts itself: a real child process, on loopback.

The world listens before it starts its workers, so a child that finds nothing
listening fails at once (``--wait 0``): its world is gone, and there is nothing
to wait for.
"""

from __future__ import annotations

import asyncio
import time

import pytest

from cas_async.scenario._processes._children import Children
from tests.processes_support import free_endpoint

pytest.importorskip("zenoh")

EXIT_LIMIT = 20.0
"""Wall seconds the child may take to exit (the Zenoh client gives up in ~0.6 s)."""


async def test_a_child_whose_world_does_not_listen_exits_at_once_saying_why() -> None:
    exits: list[tuple[int, str]] = []
    gone = asyncio.Event()

    def exited(pid: int, code: int, said: str) -> None:
        exits.append((code, said))
        gone.set()

    children = Children(exited)
    endpoint = free_endpoint()  # nothing listens there
    began = time.monotonic()
    await children.spawn(1, endpoint, None)
    try:
        await asyncio.wait_for(gone.wait(), EXIT_LIMIT)
    finally:
        children.kill()
        await children.reap(hurry=True)
    # Well before the 30 s a worker started by hand waits for its world by default.
    assert time.monotonic() - began < EXIT_LIMIT
    [(code, said)] = exits
    assert code == 2, said
    assert f"cannot connect to {endpoint}:" in said
    assert "nothing listens" not in said
