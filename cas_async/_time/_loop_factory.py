"""Choosing and running the event loop: uvloop when available, or virtual time.

``cas_async.run(main())`` is ``asyncio.run`` with the loop this package wants:
uvloop when it is installed (set ``CAS_ASYNC_UVLOOP=0`` or pass ``use_uvloop=False``
to opt out), or the virtual-time loop when ``virtual=True``. The stdlib loop it
makes waits out timers to the microsecond (:mod:`cas_async._time._precise_selector`);
uvloop's timers keep whole milliseconds.
"""

from __future__ import annotations

import asyncio
import importlib.util
import os
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

from ._precise_selector import precise_selector_available
from ._virtual_loop import VirtualTimeLoop

__all__ = ["loop_factory", "run", "uvloop_available"]

T = TypeVar("T")


def uvloop_available() -> bool:
    """True when uvloop can be imported on this platform."""
    return importlib.util.find_spec("uvloop") is not None


def _uvloop_wanted(use_uvloop: bool | None) -> bool:
    if use_uvloop is None:
        use_uvloop = os.environ.get("CAS_ASYNC_UVLOOP", "1").strip().lower() not in {
            "0",
            "false",
            "no",
            "off",
        }
    return use_uvloop and uvloop_available()


def loop_factory(
    *, virtual: bool = False, use_uvloop: bool | None = None
) -> Callable[[], asyncio.AbstractEventLoop]:
    """The factory of the loop :func:`run` would use, for ``asyncio.Runner`` and fixtures.

    Args:
        virtual: virtual time (always the stdlib-based :class:`VirtualTimeLoop`).
        use_uvloop: ``None`` follows ``CAS_ASYNC_UVLOOP`` (default on); ``False``
            forces the stdlib loop (with microsecond timers on Linux, which
            scaled runs at large time factors want). Ignored when ``virtual`` is true.
    """
    if virtual:
        return VirtualTimeLoop
    if _uvloop_wanted(use_uvloop):
        import uvloop

        factory: Callable[[], asyncio.AbstractEventLoop] = uvloop.new_event_loop
        return factory
    if precise_selector_available():
        return _precise_stdlib_loop
    return asyncio.new_event_loop


def _precise_stdlib_loop() -> asyncio.AbstractEventLoop:
    from ._precise_selector import PreciseEpollSelector  # defined on Linux only

    return asyncio.SelectorEventLoop(PreciseEpollSelector())


def run(
    main: Coroutine[Any, Any, T], *, virtual: bool = False, use_uvloop: bool | None = None
) -> T:
    """Runs ``main`` to completion on a new loop and closes it, like ``asyncio.run``.

    Args:
        main: the coroutine to run.
        virtual: run on virtual time (pair with :class:`~cas_async._time._clock.VirtualClock`).
        use_uvloop: see :func:`loop_factory`.
    """
    with asyncio.Runner(loop_factory=loop_factory(virtual=virtual, use_uvloop=use_uvloop)) as r:
        return r.run(main)
