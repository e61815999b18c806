"""How a worker process joins its world: it connects, says hello, and is welcomed (or refuses).

A worker (``python -m cas_async worker --connect ENDPOINT``, or a child of ``run
--processes``) links to the world's Zenoh router as a client, waiting for it to
listen if it is not there yet (:func:`connected`), and sends :class:`~._control.Hello`
through the world's lobby (:mod:`._lobby`) until the world answers with its
:class:`~._control.Welcome`: the run's scenario and this worker's share of the
robots (:func:`join`). A worker that cannot run the scenario on its host tells the
world why (:func:`refuse`), so that the world stops waiting for it.

An answer that does not check against the worker's key is the world's
:class:`~._control.Refused` (the keys differ) or anyone's garbage: nobody without
the key can tell them apart. So no such answer decides at once: the worker goes
on saying hello, a signed answer wins, and only after :data:`REFUSAL_GRACE` with
nothing but such answers does it conclude that its key is not the world's. The
world answers in milliseconds, so a stranger answering first cannot stop a worker
joining, and a worker with the wrong key is told within the grace.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import secrets
import sys
import time
from typing import Any, Final

from ..._errors import ConfigurationError
from ..._wire._swarm_key import SwarmKey
from ...transport.zenoh import import_zenoh, loopback_config
from ._control import WORLD, Channel, Control, Failed, Full, Hello, Welcome
from ._lobby import LOBBY, lobby_of
from ._lost import WorkerLost, within

__all__ = ["CONNECT_WAIT", "REFUSAL_GRACE", "connected", "join", "refuse"]

CONNECT_WAIT: Final = 30.0
"""Wall seconds a worker waits, by default, for its world to listen (``worker --wait``)."""
CONNECT_AGAIN: Final = 0.25
"""Wall seconds between two tries to connect to a world that does not listen yet."""
_HELLO_EVERY: Final = 0.25
REFUSAL_GRACE: Final = 2.0
"""Wall seconds a worker that was answered only with what does not check (a Refused of
another key, or a stranger's garbage) goes on waiting for a signed answer."""
_REFUSAL_LIMIT: Final = 5.0
"""Wall seconds a worker that refuses the run waits for the world to hear it."""
_REFUSAL_FLUSH: Final = 0.2
"""Wall seconds a worker that refuses the run keeps its session open for its word to go."""


async def join(
    connect: str,
    key: SwarmKey | None,
    limit: float,
    wait: float = 0.0,
    *,
    refusal_grace: float = REFUSAL_GRACE,
) -> Welcome:
    """Joins the world at ``connect`` through its lobby; returns its :class:`Welcome`.

    Raises:
        ConfigurationError: nothing listens at ``connect`` within ``wait`` wall seconds
            (see :func:`connected`), the world has its workers, or every answer for
            ``refusal_grace`` wall seconds did not check (the keys differ).
        WorkerLost: no answer within ``limit`` wall seconds (no world there, or a wrong key).
    """
    session = await connected(connect, wait)
    nonce = secrets.token_hex(8)
    answer: asyncio.Future[Control] = asyncio.get_running_loop().create_future()
    unchecked: list[tuple[float, str]] = []  # when the first answer that did not check came

    def handle(suffix: str, sender: int, message: Control) -> None:
        if suffix == f"welcome/{nonce}" and sender == WORLD and not answer.done():
            answer.set_result(message)

    def refused(suffix: str, reason: str) -> None:
        if suffix == f"welcome/{nonce}" and reason in ("unsigned", "malformed") and not unchecked:
            unchecked.append((time.monotonic(), reason))

    routers = [str(zid) for zid in session.info.routers_zid()]
    prefix = lobby_of(routers[0]) if routers else LOBBY
    lobby = Channel(session, prefix, int(nonce, 16) & 0x7FFFFFFF, key, handle, refused)
    try:
        lobby.listen(f"welcome/{nonce}")
        deadline = time.monotonic() + limit
        while not answer.done():
            now = time.monotonic()
            if unchecked and now - unchecked[0][0] > refusal_grace:
                raise ConfigurationError(
                    f"worker: the world at {connect} signs with another key than this "
                    f"worker's ({unchecked[0][1]} answers only, for {refusal_grace:g} s): "
                    f"start the worker with the world's key file (--key-file, or "
                    f"{SwarmKey.ENV_VAR})"
                )
            if now > deadline:
                raise WorkerLost(f"worker: no answer from a world at {connect} (a wrong key?)")
            if not list(session.info.routers_zid()):  # it was there: zenoh.open connected
                raise WorkerLost(f"worker: the world at {connect} went away before it answered")
            lobby.send(f"hello/{nonce}", Hello(nonce, time.time(), os.getpid()))
            with contextlib.suppress(WorkerLost):
                await within(asyncio.shield(answer), _HELLO_EVERY, "the world's welcome")
        message = answer.result()
    finally:
        lobby.close()
        session.close()
    match message:
        case Welcome():
            return message
        case Full(workers=workers):
            raise ConfigurationError(f"worker: the world at {connect} has its {workers} workers")
    raise WorkerLost(f"worker: the world at {connect} answered {type(message).__name__}")


async def connected(connect: str, wait: float) -> Any:
    """A Zenoh client session linked to the world's router at ``connect``.

    A worker may start before its world listens (a launcher starts every process at
    once, or the world is still building its robots): it tries again every
    :data:`CONNECT_AGAIN` for ``wait`` wall seconds, and says once on stderr that it waits.

    Raises:
        ConfigurationError: nothing listened at ``connect`` within ``wait``.
    """
    zenoh = import_zenoh()
    deadline, said = time.monotonic() + wait, False
    while True:
        config = loopback_config(mode="client", listen=[], connect=[connect])
        try:
            return await asyncio.to_thread(zenoh.open, config)
        except Exception as exc:
            if time.monotonic() >= deadline:
                within_wait = f" within {wait:g} s" if wait > 0 else ""
                raise ConfigurationError(
                    f"worker: cannot connect to {connect}{within_wait}: {exc}"
                ) from exc
        if not said:
            print(f"worker: nothing listens at {connect} yet; trying again for up to "
                  f"{wait:g} s", file=sys.stderr)  # fmt: skip
            said = True
        await asyncio.sleep(CONNECT_AGAIN)


async def refuse(connect: str, key: SwarmKey | None, welcome: Welcome, error: str) -> None:
    """Tells the world that the run cannot start here, and why (it stops waiting for us)."""
    zenoh = import_zenoh()
    config = loopback_config(mode="client", listen=[], connect=[connect])
    with contextlib.suppress(Exception):  # the error is said here anyway
        session = await asyncio.to_thread(zenoh.open, config)
        try:
            channel = Channel(session, welcome.namespace, welcome.index, key, lambda *_: None)
            await channel.send_when_heard(
                "world", Failed(error, configuration=True), _REFUSAL_LIMIT
            )
            await asyncio.sleep(_REFUSAL_FLUSH)  # a put on its way when the session closes is lost
        finally:
            session.close()
