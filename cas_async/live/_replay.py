"""A finished run, replayed in the live view's page: :class:`ReplayView`.

The page is the live view's; the hello says ``"mode": "replay"`` and adds every
sample's instant (``times``), the recorded events (``events``) and the end. The
page plays the run itself: it asks for the instant it wants to show with
``{"type": "seek", "t": T}`` and gets the frame of the last sample at or before
``T`` (one request at a time, so a slow page never piles requests up).
Nothing runs: everything comes from the run directory (:class:`Recording`).
"""

from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path
from typing import Any, Final, final

from .. import ConfigurationError
from ..transport import InsecureBindWarning
from ._limits import ServerLimits
from ._protocol import encode_frame, hello, text
from ._recording import Recording
from ._run_files import RecordingError
from ._server import ViewServer, is_loopback
from ._viewer import Viewer
from ._websocket import CloseCode

__all__ = ["ReplayView"]

_FLOAT_MAX: Final = int(sys.float_info.max)


@final
class ReplayView:
    """Serves a run directory's replay on one port of the running loop.

    Use it as ``async with ReplayView(run_dir, port=0) as view: ...``; the
    command line's ``view RUN_DIR`` serves one until it is interrupted.

    Args:
        run_dir: a finished run's output directory.
        host: where to listen (loopback by default; another address warns).
        port: 0 picks a free one (:attr:`url` tells which).
        limits: the server's time-outs and cap on connections.

    Raises:
        RecordingError: the directory cannot be replayed (naming the file at fault).
    """

    def __init__(
        self,
        run_dir: Path,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        limits: ServerLimits | None = None,
    ) -> None:
        self.recording = Recording(run_dir)
        self._host, self._port = host, port
        self._server = ViewServer(self._opened, self._received, limits=limits)
        self._hello = text(self._hello_message())

    async def __aenter__(self) -> ReplayView:
        """Listens.

        Raises:
            ConfigurationError: the address cannot be bound.
        """
        if not is_loopback(self._host):
            warnings.warn(
                f"replay: listening on {self._host}, beyond this machine: anyone who can reach "
                "it sees the run (the view has no authentication)",
                InsecureBindWarning,
                stacklevel=2,
            )
        try:
            await self._server.start(self._host, self._port)
        except OSError as exc:
            raise ConfigurationError(
                f"replay: cannot listen on {self._host} port {self._port}: {exc.strerror or exc}"
            ) from None
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        """Closes every viewer and stops listening."""
        self._server.close(CloseCode.GOING_AWAY, "the replay server stopped")

    @property
    def url(self) -> str:
        """The page's address."""
        return self._server.url

    @property
    def port(self) -> int:
        """The port listened on."""
        return self._server.port

    def _hello_message(self) -> dict[str, Any]:
        recording = self.recording
        info = recording.info
        events: list[dict[str, Any]] = [
            {"type": "exchange", "t": t, "count": count} for t, count in recording.exchanges
        ]
        events += [
            {"type": "delivered", "t": t, "count": k + 1}
            for k, t in enumerate(recording.deliveries)
        ]
        events.sort(key=lambda event: float(event["t"]))
        kind = info["kind"]
        return hello(
            "replay",
            app=info["app"],
            scenario=info["scenario"],
            seed=info["seed"],
            world=recording.world,
            robots=recording.robots,
            groups=recording.groups,
            scene=recording.scene,
            measures=recording.measures,
            target=info["target"],
            words=(
                info["item_name"],
                info["verb"],
                "exchanges" if kind == "items" else "events",  # results.json keeps no name for it
            ),
            kind=kind,
            times=recording.times,
            events=events,
            end=info["end"],
        )

    def _opened(self, viewer: Viewer) -> None:
        viewer.send_text(self._hello)
        if len(self.recording):
            self._send(viewer, 0)

    def _received(self, viewer: Viewer, message: dict[str, Any]) -> None:
        """A viewer's request: ``{"type": "seek", "t": T}``; anything else is ignored.

        ``T`` is a number: before the first sample, the first is sent; after the
        last (an infinity, or an integer of 400 digits), the last.
        """
        t = message.get("t")
        if message.get("type") != "seek" or isinstance(t, bool) or not isinstance(t, int | float):
            return
        if isinstance(t, int):  # JSON integers have no bound; past a float's range, the end
            t = (math.inf if t > 0 else -math.inf) if abs(t) > _FLOAT_MAX else float(t)
        if math.isnan(t) or not len(self.recording):
            return
        try:
            self._send(viewer, self.recording.index_at(t))
        except RecordingError as exc:  # the file changed since it was read: say so, keep serving
            viewer.send_text(text({"type": "error", "message": str(exc)}))

    def _send(self, viewer: Viewer, index: int) -> None:
        sample = self.recording.sample(index)
        last = index == len(self.recording) - 1
        viewer.send_frame(
            encode_frame(
                sample.t,
                sample.index,
                sample.done,
                sample.detail,
                sample.measures,
                sample.xy,
                sample.carrying,
                final=last,
            )
        )
