"""SIGINT and SIGTERM for the command line: what a signal does depends on where the run is.

``python -m cas_async run`` stops within a second of either signal, at any moment,
and exits 130. What a signal does changes as the run goes on (:class:`Interrupts`):

* before anything started (imports, reading the scenario, building the robots):
  the work in hand is abandoned at once: the process exits 130 when it is the
  command's own (during the imports, before the command line takes over, too: see
  :func:`exit_on_signal`), else :class:`Interrupted` is raised;
* while the event loop runs the robots: an action asks the run to stop;
* while results are written: the signal is noted, and acted on once they are.

This module imports nothing but the standard library: ``cas_async.__main__`` imports
it before anything that takes time.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Final, final

__all__ = ["Interrupted", "Interrupts", "exit_on_signal"]

SIGNALS: Final = (signal.SIGINT, signal.SIGTERM)
EXIT_INTERRUPTED: Final = 130


class Interrupted(BaseException):
    """A signal arrived where abandoning the work in hand loses nothing.

    A ``BaseException``, as ``KeyboardInterrupt`` is: ``except Exception`` in the
    abandoned code does not swallow it.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(f"interrupted by {signal.Signals(signum).name}")
        self.signum = signum


@final
class Interrupts:
    """The process's SIGINT and SIGTERM handler while the command line runs.

    By default a signal raises :class:`Interrupted`; :meth:`calling` runs an
    action instead, :meth:`deferred` only notes it. Every signal is noted in
    :attr:`received`. Outside the main thread (where Python cannot handle
    signals) nothing is installed and nothing is received.
    """

    def __init__(self) -> None:
        self.received: list[int] = []
        """The signals that arrived, in order."""
        self._action: Callable[[], None] | None = None
        self._deferred = False
        self._previous: dict[int, object] = {}

    def install(self) -> Interrupts:
        """Takes over SIGINT and SIGTERM (main thread only); returns ``self``."""
        if threading.current_thread() is threading.main_thread() and not self._previous:
            self._previous = {signum: signal.signal(signum, self._handle) for signum in SIGNALS}
        return self

    def restore(self) -> None:
        """Gives SIGINT and SIGTERM back to the handlers they had before :meth:`install`."""
        previous, self._previous = self._previous, {}
        for signum, handler in previous.items():
            signal.signal(signum, handler)  # type: ignore[arg-type]

    @property
    def interrupted(self) -> bool:
        """Whether a signal arrived."""
        return bool(self.received)

    @contextlib.contextmanager
    def calling(self, action: Callable[[], None]) -> Iterator[None]:
        """Within the block a signal calls ``action`` instead of raising.

        It runs in the main thread between two bytecodes: it must only schedule
        work, as ``loop.call_soon_threadsafe`` does (or end the process).
        """
        before, self._action = self._action, action
        try:
            yield
        finally:
            self._action = before

    @contextlib.contextmanager
    def deferred(self) -> Iterator[None]:
        """Within the block a signal is only noted; look at :attr:`received` after it."""
        before, self._deferred = self._deferred, True
        try:
            yield
        finally:
            self._deferred = before

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.received.append(signum)
        if self._deferred:
            return
        if self._action is not None:
            self._action()
            return
        raise Interrupted(signum)


def exit_on_signal() -> None:
    """From now until the command line takes over, a signal exits 130 at once.

    ``python -m cas_async`` calls it first thing: importing the library and its
    dependencies takes a few tenths of a second, in which Python's own handlers
    would print a ``KeyboardInterrupt`` traceback (or die of SIGTERM). Outside the
    main thread (where Python cannot handle signals) it does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        return
    for signum in SIGNALS:
        signal.signal(signum, _exit_interrupted)


def _exit_interrupted(signum: int, frame: FrameType | None) -> None:
    # At once: an exception raised here could land in a finalizer and be dropped.
    os._exit(EXIT_INTERRUPTED)
