"""Which workers of a run across processes are alive, as far as the world can tell.

A worker is alive while it speaks: every signed control message from it counts
(:meth:`Liveness.heard`). Its liveliness token going is a hint, never proof
(anyone on the network can declare and undeclare a token of any name): when it
goes, the world asks whether a token of that name still answers, and only when
none does is the worker *suspect*: it then has :data:`~._control.SUSPECT_LIMIT`
wall seconds to say something. Any worker silent for ``run.window_limit`` is lost
too (frozen, or cut off). A lost worker is named with its robots.

Tokens that no process of the run holds are counted (:attr:`Liveness.tokens`,
in ``results.json``'s ``protocol_errors``), and change nothing: ``token.unknown``,
a token that came or went under a name of the run's namespace that is none of its
processes' (``worker/7`` of two workers, ``worker/x``); ``token.forged``, the
going of a token whose process still holds it (the world's own, or a worker's
whose token still answers): someone else's token of that name went.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any, final

from ...transport.zenoh import import_zenoh
from ._control import SUSPECT_LIMIT, token_lives
from ._lost import WorkerLost

__all__ = ["Liveness"]


@final
class Liveness:
    """What the world knows of its workers' lives (see the module docs).

    Args:
        workers: how many workers there are (``0..workers-1``).
        limit: wall seconds of silence after which any worker is lost.
        robots_of: ``"; its N robots are lost: ..."`` for some workers.
        news: called when a worker becomes suspect (the world looks again).
    """

    def __init__(
        self,
        workers: int,
        limit: float,
        robots_of: Callable[[Sequence[int]], str],
        news: Callable[[], None],
    ) -> None:
        self._workers = workers
        self._limit = limit
        self._robots_of = robots_of
        self._news = news
        self._suspect: set[int] = set()  # workers whose token went: to prove they live
        self._last_word: dict[int, float] = {}  # a worker -> when it last said something
        self._gone: set[int] = set()  # workers that said Bye: their token goes, rightly
        self._checks: list[asyncio.Task[None]] = []
        self._subscriber: Any = None
        self.tokens: dict[str, int] = {}
        """Tokens that no process of the run holds, counted by reason (``token.<reason>``)."""

    def watch(self, session: Any, namespace: str) -> None:
        """Follows the liveliness tokens under ``namespace`` (call on the loop).

        The world holds ``{namespace}/world`` from before this call until after
        :meth:`close`: its going meanwhile is a stranger's token of that name.
        """
        loop = asyncio.get_running_loop()
        workers = {f"{namespace}/worker/{index}": index for index in range(self._workers)}
        world = f"{namespace}/world"

        def token(sample: Any) -> None:  # on a Zenoh thread
            key = str(sample.key_expr)
            gone = sample.kind == import_zenoh().SampleKind.DELETE
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                if key in workers:
                    if gone:
                        loop.call_soon_threadsafe(self._check, session, key, workers[key])
                elif key == world:
                    if gone:
                        loop.call_soon_threadsafe(self._count, "token.forged")
                else:
                    loop.call_soon_threadsafe(self._count, "token.unknown")

        self._subscriber = session.liveliness().declare_subscriber(f"{namespace}/**", token)

    def heard(self, worker: int) -> None:
        """``worker`` said something signed: it lives."""
        self._suspect.discard(worker)
        self._last_word[worker] = time.monotonic()

    def said_bye(self, worker: int) -> None:
        """``worker`` is done: its token going is no news."""
        self._gone.add(worker)

    def silent(self, workers: Iterable[int], since: float) -> list[int]:
        """Those of ``workers`` silent for too long (``since``: when waiting began)."""
        now = time.monotonic()
        return [
            w
            for w in workers
            if now - max(since, self._last_word.get(w, since))
            > (SUSPECT_LIMIT if w in self._suspect else self._limit)
        ]

    def lost(self, who: Sequence[int], where: str = "") -> WorkerLost:
        """The loss of workers ``who`` that said nothing for too long (``where``: waiting for)."""
        gone = all(w in self._suspect for w in who)
        many = len(who) > 1
        are = "are" if many else "is"
        return WorkerLost(
            f"worker{'s' if many else ''} {', '.join(map(str, who))} "
            + (
                f"{are} gone: {'their tokens' if many else 'its token'} went and no word came"
                f"{where} within {SUSPECT_LIMIT:g} s"
                if gone
                else f"{are} frozen or cut off: no word{where} within {self._limit:g} s "
                "(run.window_limit)"
            )
            + self._robots_of(who)
        )

    def close(self) -> None:
        """Stops following the tokens."""
        for check in self._checks:
            check.cancel()
        if self._subscriber is not None:
            with contextlib.suppress(Exception):
                self._subscriber.undeclare()
            self._subscriber = None

    def _count(self, reason: str) -> None:
        self.tokens[reason] = self.tokens.get(reason, 0) + 1

    def _check(self, session: Any, key: str, index: int) -> None:
        self._checks.append(asyncio.ensure_future(self._suspect_unless_alive(session, key, index)))

    async def _suspect_unless_alive(self, session: Any, key: str, index: int) -> None:
        """A worker whose token no longer answers is suspect: it has SUSPECT_LIMIT to speak."""
        if index in self._gone:
            return
        if await asyncio.to_thread(token_lives, session, key):
            self._count("token.forged")  # another session's token of that name went
            return
        self._suspect.add(index)
        self._news()
