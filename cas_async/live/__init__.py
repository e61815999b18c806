"""Watching a swarm: live in the browser, a replay of any run, MCAP recordings.

* :class:`LiveView`: serves a running :class:`~cas_async.scenario.ScenarioRun`'s
  view on one port of the caller's event loop (what ``run --live`` does): a
  self-contained page, and a WebSocket of frames and events;
* :class:`ReplayView`: the same page over a finished run's directory, with
  play, pause, speed and a time scrubber (``view RUN_DIR``);
* :class:`Recording`: a run directory read back (``trace.csv``, ``results.json``,
  ``scene.json``); :func:`export_mcap` writes it as a ROS 2 bag in MCAP
  (``export RUN_DIR --format mcap``; needs the ``mcap`` extra);
* :func:`decode_frame`: the protocol's binary frame, for a client of one's own
  (the protocol is described in ``docs/live.md``);
* :class:`ServerLimits`: the server's time-outs and its cap on connections.

Only the standard library serves the page: the WebSocket server is this
package's own (see ``docs/live.md`` for why).
"""

from ._export import export_mcap
from ._limits import ServerLimits
from ._live import LiveView
from ._protocol import PROTOCOL, UNKNOWN, Frame, decode_frame
from ._recording import Recording, Sample, write_scene
from ._replay import ReplayView
from ._run_files import RecordingError

__all__ = [
    "Frame",
    "LiveView",
    "PROTOCOL",
    "Recording",
    "RecordingError",
    "ReplayView",
    "Sample",
    "ServerLimits",
    "UNKNOWN",
    "decode_frame",
    "export_mcap",
    "write_scene",
]
