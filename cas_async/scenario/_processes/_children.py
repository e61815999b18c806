"""The worker processes a world starts itself (``run --processes N``): spawned, watched, reaped.

Each child is ``python -m cas_async worker --connect ENDPOINT --quiet --wait 0`` with the
run's key in its environment. Its stderr passes through to the world's (the last
lines are kept, to say why it went), and its exit is reported at once, with the
code and those lines: the world decides whether it is a loss (a worker that
exits before its ``Bye``).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
from collections.abc import Callable
from typing import Final, final

from ..._wire._swarm_key import SwarmKey
from ._control import HURRY_LIMIT
from ._lost import WorkerLost, within

__all__ = ["Children"]

STDERR_LINES: Final = 12
"""Lines of a child's stderr kept to say why it exited."""
REAP_LIMIT: Final = 5.0
"""Wall seconds a child has to exit once the run is over, before it is killed."""

Exited = Callable[[int, int, str], None]
"""``exited(pid, code, said)``: a child exited with ``code``; ``said``: its last words."""


@final
class Children:
    """The child worker processes of one world (see the module docs).

    Args:
        exited: called on the event loop when a child exits (see :data:`Exited`).
    """

    def __init__(self, exited: Exited) -> None:
        self._exited = exited
        self._processes: list[asyncio.subprocess.Process] = []
        self._watchers: list[asyncio.Task[None]] = []

    async def spawn(self, count: int, endpoint: str, key: SwarmKey | None) -> None:
        """Starts ``count`` workers that join the world listening at ``endpoint``."""
        env = {**os.environ}
        if key is not None:
            env[SwarmKey.ENV_VAR] = key.secret.hex()
        for _ in range(count):  # the world listens already: a worker that finds none, fails
            child = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "cas_async", "worker", "--connect", endpoint, "--quiet",
                "--wait", "0",
                env=env, stdin=asyncio.subprocess.DEVNULL, stderr=asyncio.subprocess.PIPE,
            )  # fmt: skip
            self._processes.append(child)
            self._watchers.append(asyncio.ensure_future(self._watch(child)))

    def exited(self) -> set[int]:
        """The process ids of the children that have exited."""
        return {child.pid for child in self._processes if child.returncode is not None}

    async def reap(self, *, hurry: bool = False) -> None:
        """Waits for every child to exit (``REAP_LIMIT`` each, together), kills the rest.

        ``hurry``: the run was stopped (a signal): :data:`~._control.HURRY_LIMIT` instead.
        """
        limit = HURRY_LIMIT if hurry else REAP_LIMIT
        await asyncio.gather(*(self._reap(child, limit) for child in self._processes))
        for watcher in self._watchers:
            watcher.cancel()

    def kill(self) -> None:
        """Kills every child still running, at once (their exits are reaped later, if ever)."""
        for child in self._processes:
            if child.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    child.kill()

    async def _watch(self, child: asyncio.subprocess.Process) -> None:
        """Passes the child's stderr on, keeps its last lines, reports its exit.

        A child's own ``error: ...`` line is kept, not passed on: the world's error
        names the worker and repeats it, once.
        """
        lines: list[str] = []
        assert child.stderr is not None
        async for raw in child.stderr:
            line = raw.decode(errors="replace")
            if not line.startswith("error: "):
                sys.stderr.write(line)
            lines.append(line.rstrip())
            del lines[:-STDERR_LINES]
        code = await child.wait()
        said = "; ".join(line for line in lines[-3:] if line) or "nothing on stderr"
        self._exited(child.pid, code, said)

    @staticmethod
    async def _reap(child: asyncio.subprocess.Process, limit: float) -> None:
        with contextlib.suppress(WorkerLost):
            await within(child.wait(), limit, "a worker to exit")
        if child.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                child.kill()
            await child.wait()
