"""A running scenario's live view: :class:`LiveView`, served on the caller's own event loop.

The command line's ``run --live`` uses exactly this::

    run = ScenarioRun(scenario)
    async with LiveView(run, port=0, fps=10) as view:   # listens; the run is not started
        print("live view:", view.url)
        await view.wait_for_viewer()                     # optional: --live-wait
        async with run:
            await run.until_done()
    # leaving sends the run's last frame and its end to every viewer, then closes

The view is a :class:`~cas_async.scenario.RunListener` of the run: each frame is
a sample of the run's own sampler (the rows of ``trace.csv``), sent at most
``fps`` times per wall second; the samples in between are skipped, and a viewer
that reads slowly only ever gets the latest frame (see :mod:`._server`). With
``pace``, a run on virtual time is held to that many simulated seconds per wall
second (see :class:`~cas_async.live._pacer.Pacer`): the results do not change.
"""

from __future__ import annotations

import asyncio
import math
import socket
import time
import warnings
from collections.abc import Callable
from typing import Any, Final, final

import numpy as np
import numpy.typing as npt

from .. import ConfigurationError, VirtualTimeLoop
from ..scenario import ScenarioRun
from ..sim import ItemEvent, ItemEventKind
from ..transport import InsecureBindWarning
from ._limits import ServerLimits
from ._pacer import Pacer, wall_bounded
from ._protocol import encode_frame, hello, text
from ._server import ViewServer, is_loopback
from ._viewer import Viewer

__all__ = ["LiveView"]

EVENT_LIMIT: Final = 1000
"""Events kept between two sends; past it the oldest are dropped (and counted)."""
CLOSE_LIMIT: Final = 2.0
"""Wall seconds the view waits for its viewers to take the end before it cuts them."""


@final
class LiveView:
    """Serves ``run``'s live view on one port of the running loop (see the module docs).

    Args:
        run: the run to show; the view listens to it from ``async with`` on.
        host: where to listen: loopback by default; another address warns
            (:class:`~cas_async.transport.InsecureBindWarning`): anyone who
            reaches it sees the run.
        port: 0 picks a free port (:attr:`url` tells which).
        fps: frames per wall second, at most.
        pace: simulated seconds per wall second for a run on virtual time;
            ``None`` runs it as fast as it goes.
        stop: when set, the view stops holding the run (pace) and waiting for a viewer.
        sock: a listening socket to serve on instead (``host`` and ``port`` are then
            its own); the view closes it.
        wall_clock: reads the wall clock (seconds).
        block: blocks the loop's thread for some wall seconds (pacing only).
        limits: the server's time-outs and cap on connections.

    Raises:
        ValueError: ``fps`` or ``pace`` is not a positive number.
    """

    def __init__(
        self,
        run: ScenarioRun,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        fps: float = 10.0,
        pace: float | None = None,
        stop: asyncio.Event | None = None,
        sock: socket.socket | None = None,
        wall_clock: Callable[[], float] = time.perf_counter,
        block: Callable[[float], None] = time.sleep,
        limits: ServerLimits | None = None,
    ) -> None:
        if not (0 < fps < math.inf):
            raise ValueError(f"LiveView: fps must be a positive number, got {fps!r}")
        self._run = run
        self._host, self._port, self._fps = host, port, fps
        self._stop = stop
        self._sock = sock
        if sock is not None:
            self._host, self._port = sock.getsockname()[:2]
        self._wall = wall_clock
        self._pacer = None if pace is None else Pacer(
            pace, wall_clock=wall_clock, block=block, stopping=self._stopping
        )  # fmt: skip
        self._server = ViewServer(self._opened, limits=limits)
        self._ids = list(run.trace.ids)
        self._measures = dict(run.mission.measures)
        self._seq = -1
        self._latest: tuple[float, npt.NDArray[np.float64], npt.NDArray[np.bool_]] | None = None
        self._latest_sent = -1  # the seq of the last frame sent
        self._last_wall = -math.inf  # when the last frame went
        self._last_events = -math.inf  # when the last events went
        self._events: list[dict[str, Any]] = []
        self._dropped = 0
        self._tally = (0, 0)
        self._open = False
        self.frames_sent = 0
        """Frames broadcast (each to every viewer then connected)."""

    # -- lifecycle ---------------------------------------------------------------------

    async def __aenter__(self) -> LiveView:
        """Listens, and starts following the run.

        Raises:
            ConfigurationError: ``pace`` was given but the loop is not on virtual
                time, or the address cannot be bound.
        """
        if self._pacer is not None and not isinstance(asyncio.get_running_loop(), VirtualTimeLoop):
            raise ConfigurationError(
                "live view: pace holds a run on virtual time; this run is on scaled real time "
                "(its pace is its time factor): leave pace out, or run it on virtual time"
            )
        if self._sock is None and not is_loopback(self._host):
            warnings.warn(
                f"live view: listening on {self._host}, beyond this machine: anyone who can "
                "reach it sees the run (the view has no authentication); listen on 127.0.0.1 "
                "and forward the port (ssh -L) to watch from elsewhere",
                InsecureBindWarning,
                stacklevel=2,
            )
        try:
            await self._server.start(self._host, self._port, self._sock)
        except OSError as exc:
            raise ConfigurationError(
                f"live view: cannot listen on {self._host} port {self._port}: {exc.strerror or exc}"
            ) from None
        self._open = True
        self._run.listen(self)
        self._run.environment.items.subscribe(self._item)
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        """Sends the run's last frame and its end to every viewer, then closes."""
        await self.close()

    async def close(self) -> None:
        """What leaving the ``async with`` block does; idempotent."""
        if not self._open:
            return
        self._open = False
        server = self._server
        if server.viewers and self._latest is not None and self._latest_sent != self._seq:
            wait = self._last_wall + 1 / self._fps - self._wall()  # at most fps, the last too
            if wait > 0:
                await wall_bounded(asyncio.Event().wait(), wait)
            self._send_latest(final=True)
        self._flush_events()
        result = self._run.result
        server.broadcast_text(
            text(
                {
                    "type": "end",
                    "t": result.sim_time,
                    "status": str(result.status),
                    "makespan": result.makespan,
                    "done": result.delivered,
                }
            )
        )
        server.close()
        await wall_bounded(server.gone(), CLOSE_LIMIT)
        server.abort()  # those that did not take their close frame in time

    @property
    def url(self) -> str:
        """The page's address, once listening (``http://127.0.0.1:PORT/``)."""
        return self._server.url

    @property
    def port(self) -> int:
        """The port listened on (the one picked, for port 0)."""
        return self._server.port

    @property
    def skipped_frames(self) -> int:
        """Frames the connected viewers could not take in time (a later one went instead)."""
        return sum(viewer.skipped_frames for viewer in self._server.viewers)

    @property
    def viewers(self) -> int:
        """How many viewers are connected now."""
        return len(self._server.viewers)

    async def wait_for_viewer(self) -> bool:
        """Returns ``True`` once a viewer is connected, ``False`` if ``stop`` is set first."""
        connected = asyncio.ensure_future(self._server.connected.wait())
        waits = {connected}
        if self._stop is not None:
            waits.add(asyncio.ensure_future(self._stop.wait()))
        try:
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for task in waits:
                task.cancel()
        return self._server.connected.is_set() and not self._stopping()

    def _stopping(self) -> bool:
        return self._stop is not None and self._stop.is_set()

    # -- the run's listener ------------------------------------------------------------

    def sampled(
        self, t: float, xy: npt.NDArray[np.float64], carrying: npt.NDArray[np.bool_]
    ) -> None:
        """A sample of the run: sent when a frame is due and someone watches."""
        self._seq += 1
        self._latest = (t, xy, carrying)
        if self._server.viewers and self._wall() - self._last_wall >= 1 / self._fps:
            self._send_latest()

    def changed(self, t: float) -> None:
        """The objective's progress changed: an event."""
        tally = tuple(self._run.objective.progress())
        if tally != self._tally:
            self._tally = (tally[0], tally[1])
            self._event({"type": "progress", "t": t, "done": tally[0], "detail": tally[1]})

    async def hold(self, t: float) -> None:
        """Paces the run, when asked to."""
        if self._pacer is not None:
            await self._pacer.hold(t)

    def _item(self, event: ItemEvent) -> None:
        if not self._open:
            return
        if event.kind is ItemEventKind.TRANSFERRED:
            self._event(
                {
                    "type": "exchange",
                    "t": event.t,
                    "item": event.item,
                    "from": event.robot,
                    "to": event.receiver,
                    "count": self._run.environment.items.transfers,
                }
            )
        elif event.kind is ItemEventKind.RETIRED:
            self._event(
                {
                    "type": "delivered",
                    "t": event.t,
                    "item": event.item,
                    "by": event.robot,
                    "count": self._run.environment.items.retired,
                }
            )

    # -- sending -----------------------------------------------------------------------

    def _event(self, event: dict[str, Any]) -> None:
        if not self._open or not self._server.viewers:
            return
        if len(self._events) >= EVENT_LIMIT:
            del self._events[0]
            self._dropped += 1
        self._events.append(event)
        if self._wall() - self._last_events >= 1 / self._fps:  # else with the next frame
            self._flush_events()

    def _flush_events(self) -> None:
        if not self._events and not self._dropped:
            return
        message = {"type": "events", "events": self._events, "dropped": self._dropped}
        self._server.broadcast_text(text(message))
        self._events, self._dropped = [], 0
        self._last_events = self._wall()

    def _send_latest(self, *, final: bool = False) -> None:
        assert self._latest is not None
        self._flush_events()
        self._server.broadcast_frame(self._frame(final=final))
        self._latest_sent = self._seq
        self._last_wall = self._wall()
        self.frames_sent += 1

    def _frame(self, *, final: bool = False) -> bytes:
        assert self._latest is not None
        t, xy, carrying = self._latest
        done, detail = self._run.objective.progress()
        measures = [float(measure(self._ids, xy)) for measure in self._measures.values()]
        return encode_frame(t, self._seq, done, detail, measures, xy, carrying, final=final)

    def _opened(self, viewer: Viewer) -> None:
        """A new viewer: the hello, then the latest frame at once."""
        viewer.send_text(text(self._hello()))
        if self._latest is not None:
            viewer.send_frame(self._frame())

    def _hello(self) -> dict[str, Any]:
        run = self._run
        result = run.result
        world = result.config.get("world", {})
        return hello(
            "live",
            app=result.app,
            scenario=result.scenario,
            seed=result.seed,
            world=(float(world.get("width", 0.0)), float(world.get("height", 0.0))),
            robots=self._ids,
            groups=result.groups,
            scene=run.mission.scene,
            measures=list(self._measures),
            target=result.target,
            words=(result.item_name, result.verb, result.detail),
            kind=result.kind,
            fps=self._fps,
            pace=None if self._pacer is None else self._pacer.pace,
        )
