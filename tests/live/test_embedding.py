"""The live view as a program embeds it: on its own loop, beside a ScenarioRun (virtual time).

A viewer that never reads must not slow the run nor change what it measures; a
paced run measures what an unpaced one does; what the view adds is a listener of
the run's sampler, nothing in the robots' logic.
"""

from __future__ import annotations

import asyncio
import base64
import dataclasses
import os
import socket
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest

import cas_async
from cas_async.live import LiveView, ServerLimits
from cas_async.scenario import RunResult, ScenarioRun, load_scenario

from .helpers import FIRE

VIRTUAL = ["run.virtual=true", 'run.transport="memory"']


def _measured(result: RunResult) -> dict[str, Any]:
    data = dataclasses.asdict(result)
    del data["wall_time"]
    return data


async def _stalled_viewer(url: str) -> asyncio.StreamWriter:
    """Opens the WebSocket and then never reads again (its buffers fill, and stay full)."""
    host, port = url.removeprefix("http://").rstrip("/").rsplit(":", 1)
    reader, writer = await asyncio.open_connection(host, int(port), limit=1024)
    sock = writer.get_extra_info("socket")
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    writer.write(
        (
            f"GET /ws HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    head = await reader.readuntil(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 101")
    return writer


def _run(
    path: Path,
    view: dict[str, Any] | None,
    viewer: Callable[[str], Awaitable[asyncio.StreamWriter]] | None = None,
    overrides: tuple[str, ...] = (),
) -> tuple[RunResult, dict[str, float]]:
    scenario = load_scenario(path, [*VIRTUAL, *overrides])

    async def main() -> tuple[RunResult, dict[str, float]]:
        run = ScenarioRun(scenario)
        if view is None:
            async with run:
                await run.until_done()
            return run.result, {}
        async with LiveView(run, **view) as live:
            writer = None if viewer is None else await viewer(live.url)
            assert live.viewers == (0 if viewer is None else 1)
            began = time.perf_counter()
            async with run:
                await run.until_done()
            stats = {
                "wall": time.perf_counter() - began,
                "skipped": live.skipped_frames,
                "sent": live.frames_sent,
            }
        if writer is not None:
            writer.close()
        return run.result, stats

    return cas_async.run(main(), virtual=True)


@pytest.mark.slow  # two runs of 250 robots
def test_a_viewer_that_never_reads_changes_nothing_the_run_measures() -> None:
    scenario = FIRE / "scale_250.toml"
    often = ("run.trace_interval=0.05",)  # some 600 frames of 4.7 kB
    alone, _ = _run(scenario, None, overrides=often)
    # Small kernel buffers, as on a slow link: on loopback Linux would buffer megabytes.
    listening = socket.create_server(("127.0.0.1", 0))
    listening.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)  # the accepted ones' too
    # A viewer silent for the idle time-out is closed: this one must stay for the whole run.
    view = {"fps": 1e6, "sock": listening, "limits": ServerLimits(idle_timeout=3600.0)}
    watched, stats = _run(scenario, view, _stalled_viewer, often)
    assert watched.status == alone.status == "completed"
    assert _measured(watched) == _measured(alone)
    assert stats["sent"] > 500  # a frame per sample was due...
    assert stats["skipped"] > 0  # ...and most could not go: the latest replaced the one waiting


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
def test_pacing_holds_a_virtual_run_and_changes_nothing_it_measures() -> None:
    scenario = FIRE / "thesis_5_8_2.toml"
    alone, _ = _run(scenario, None)
    pace = 100.0
    paced, stats = _run(scenario, {"pace": pace})
    assert _measured(paced) == _measured(alone)
    assert alone.makespan is not None
    # A lower bound only: pacing makes a run last at least makespan / pace of wall time
    # (from its first sample), however fast the machine; the last second is not held.
    assert stats["wall"] >= (alone.makespan - 1.0) / pace


def test_pace_is_refused_on_scaled_time() -> None:
    scenario = load_scenario(FIRE / "thesis_5_8_2.toml", ['run.transport="memory"'])

    async def main() -> None:
        run = ScenarioRun(scenario)
        with pytest.raises(cas_async.ConfigurationError, match="virtual time"):
            async with LiveView(run, pace=2.0):
                pass

    cas_async.run(main())


def test_a_host_beyond_loopback_warns_as_an_insecure_bind() -> None:
    scenario = load_scenario(FIRE / "thesis_5_8_2.toml", VIRTUAL)

    async def main() -> None:
        run = ScenarioRun(scenario)
        with pytest.warns(cas_async.InsecureBindWarning, match="beyond this machine"):
            async with LiveView(run, host="0.0.0.0") as view:
                assert view.url.startswith("http://")

    cas_async.run(main(), virtual=True)
