"""What ``--live`` costs a run: ``scale_2500`` on virtual time, with and without one viewer.

Not part of ``python -m benchmarks`` (each run takes tens of seconds)::

    python -m benchmarks.live [--count 2500] [--runs 3] [--fps 10]

Each run is a fresh Python process (``--child``) that loads
``apps/fire_brigade/scenarios/scale_<count>.toml`` on virtual time and times the
run itself (from starting the robots to the result, as ``benchmarks.scale``
does). With the view on, the child serves a :class:`~cas_async.live.LiveView`
(``fps`` frames per wall second at most, no pace), starts one viewer in another
process (a WebSocket client that reads and decodes every message, as a page
would) and waits for it to connect before the robots start. Runs alternate
off, on, off, on... so that both see the same machine.

Reported: the median wall time of each mode, the overhead of the view
(on / off - 1), the same for the CPU time of the run's process (steadier than
the wall time on a machine that others share), the frames the viewer decoded,
and the frame's size and its cost to build (positions, carriers, the measures)
at this count.

Target (exit status 1 when it fails, or a run does not complete): the
overhead is under ``LIMIT`` (5%).

With ``--stalled N``, the view is on without a reading viewer: N stalled ones
instead, from another process, each of which reads its handshake's answer and then
nothing (its receive buffer 4 KiB), but sends an unsolicited pong every 5 s, so
that the server's idle time-out keeps it for the whole run (the worst case: a
viewer that says nothing is closed after 20 s). The run starts once all N are
connected. Target: the overhead is under ``STALLED_LIMIT`` (10%).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Final

ROOT: Final = Path(__file__).resolve().parent.parent
SCENARIOS: Final = ROOT / "apps" / "fire_brigade" / "scenarios"
FORCED: Final = ("run.virtual=true", 'run.transport="memory"')
LIMIT: Final = 0.05
STALLED_LIMIT: Final = 0.10

_VIEWER: Final = """
import asyncio, json, sys
import websockets
from cas_async.live import decode_frame

async def main(url):
    frames = 0
    async with websockets.connect(url, max_size=None) as socket:
        async for message in socket:
            if isinstance(message, bytes):
                decode_frame(message)
                frames += 1
    print(json.dumps({"frames": frames}))

asyncio.run(main(sys.argv[1]))
"""


_STALLER: Final = """
import base64, os, resource, socket, sys, time
port, count = int(sys.argv[1]), int(sys.argv[2])
soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, max(soft, count + 64)), hard))
socks = []
for _ in range(count):
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET /ws HTTP/1.1\\r\\nHost: 127.0.0.1:{port}\\r\\nUpgrade: websocket\\r\\n"
               f"Connection: Upgrade\\r\\nSec-WebSocket-Key: {key}\\r\\n"
               "Sec-WebSocket-Version: 13\\r\\n\\r\\n").encode())
    head = b""
    while b"\\r\\n\\r\\n" not in head:
        byte = s.recv(1)
        if not byte:
            sys.exit(f"the server closed a viewer's connection: {head!r}")
        head += byte
    socks.append(s)
print("connected", flush=True)
pong = bytes([0x8A, 0x80]) + b"\\0\\0\\0\\0"  # a masked, empty pong
os.set_blocking(0, False)
while True:
    try:
        if sys.stdin.buffer.read() == b"":
            break  # stdin closed: the run is over
    except (BlockingIOError, TypeError):
        pass
    time.sleep(5.0)
    for s in socks:
        try:
            s.send(pong, socket.MSG_DONTWAIT)
        except OSError:
            pass
"""


def _timed(view: Any) -> list[float]:
    """Wraps the view's ``sampled`` (where frames are built and sent) to add up its time."""
    spent = [0.0]
    sampled = view.sampled

    def timed(*args: Any) -> None:
        began = time.perf_counter()
        sampled(*args)
        spent[0] += time.perf_counter() - began

    view.sampled = timed
    return spent


def run_child(path: str, live: bool, fps: float, stalled: int = 0) -> dict[str, Any]:
    """One run in this process (see the module docs); what it measured."""
    import asyncio

    import cas_async
    from cas_async import wall_bounded
    from cas_async.live import LiveView
    from cas_async.scenario import ScenarioRun, load_scenario

    scenario = load_scenario(path, FORCED)

    async def main() -> dict[str, Any]:
        run = ScenarioRun(scenario)
        viewer: asyncio.subprocess.Process | None = None
        figures: dict[str, Any] = {}
        if live and stalled:
            async with LiveView(run, fps=fps) as view:
                staller = await asyncio.create_subprocess_exec(
                    sys.executable, "-c", _STALLER, str(view.port), str(stalled),
                    stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                )  # fmt: skip
                assert staller.stdout is not None
                assert staller.stdin is not None
                await staller.stdout.readline()
                while view.viewers < stalled:
                    await wall_bounded(asyncio.Event().wait(), 0.05)
                spent = _timed(view)
                started, cpu = time.perf_counter(), time.process_time()
                async with run:
                    await run.until_done()
                figures["wall"] = time.perf_counter() - started
                figures["cpu"] = time.process_time() - cpu
                figures["sent"] = view.frames_sent
                figures["stalled_left"] = view.viewers
                figures["skipped"] = view.skipped_frames
                figures["view_s"] = spent[0]
            staller.stdin.close()
            staller.kill()
            await staller.wait()
            figures["decoded"] = 0
        elif live:
            async with LiveView(run, fps=fps) as view:
                url = view.url.replace("http://", "ws://") + "ws"
                viewer = await asyncio.create_subprocess_exec(
                    sys.executable, "-c", _VIEWER, url, stdout=subprocess.PIPE
                )
                await view.wait_for_viewer()
                started, cpu = time.perf_counter(), time.process_time()
                async with run:
                    await run.until_done()
                figures["wall"] = time.perf_counter() - started
                figures["cpu"] = time.process_time() - cpu
                figures["sent"] = view.frames_sent
            out, _ = await viewer.communicate()
            figures["decoded"] = json.loads(out)["frames"]
        else:
            started, cpu = time.perf_counter(), time.process_time()
            async with run:
                await run.until_done()
            figures["wall"] = time.perf_counter() - started
            figures["cpu"] = time.process_time() - cpu
        figures.update(status=str(run.result.status), makespan=run.result.makespan)
        figures["robots"] = len(run.trace.ids)
        return figures

    return cas_async.run(main(), virtual=True)


def frame_cost(path: str) -> dict[str, float]:
    """The size of one frame at this count, and the median time to build one (µs)."""
    import numpy as np

    from cas_async.live._protocol import encode_frame
    from cas_async.scenario import ScenarioRun, load_scenario

    run = ScenarioRun(load_scenario(path, FORCED))
    ids = list(run.trace.ids)
    xy = np.random.default_rng(1).uniform(0, 10, (len(ids), 2))
    carrying = np.zeros(len(ids), dtype=bool)
    measures = list(run.mission.measures.values())
    times = []
    for _ in range(50):
        began = time.perf_counter()
        data = encode_frame(1.0, 1, 0, 0, [m(ids, xy) for m in measures], xy, carrying)
        times.append(time.perf_counter() - began)
    return {"bytes": len(data), "build_us": statistics.median(times) * 1e6}


def measure(path: Path, live: bool, fps: float, stalled: int = 0) -> dict[str, Any]:
    """One run in a fresh process."""
    args = [sys.executable, "-m", "benchmarks.live", "--child", str(path), "--fps", str(fps),
            "--stalled", str(stalled)]  # fmt: skip
    done = subprocess.run(
        [*args, *(["--on"] if live else [])], cwd=ROOT, capture_output=True, text=True, check=False
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or len(lines) != 1:
        raise RuntimeError(f"the run failed (exit {done.returncode}):\n{done.stderr.strip()}")
    figures: dict[str, Any] = json.loads(lines[0])
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.live", description=__doc__)
    parser.add_argument("--count", type=int, default=2500, help="scale_<count>.toml")
    parser.add_argument("--runs", type=int, default=3, help="runs per mode (median)")
    parser.add_argument("--fps", type=float, default=10.0, help="the view's frames per second")
    parser.add_argument("--stalled", type=int, default=0, help="stalled viewers instead of one")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--on", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(run_child(args.child, args.on, args.fps, args.stalled)))
        return 0
    path = SCENARIOS / f"scale_{args.count}.toml"
    runs: dict[str, list[dict[str, Any]]] = {"off": [], "on": []}
    for k in range(args.runs):
        for mode in ("off", "on"):
            figures = measure(path, mode == "on", args.fps, args.stalled)
            runs[mode].append(figures)
            print(f"run {k + 1} {mode}: {figures}", file=sys.stderr, flush=True)
    off = statistics.median(r["wall"] for r in runs["off"])
    on = statistics.median(r["wall"] for r in runs["on"])
    overhead = on / off - 1
    cpu_off = statistics.median(r["cpu"] for r in runs["off"])
    cpu_on = statistics.median(r["cpu"] for r in runs["on"])
    summary = {
        "scenario": path.stem,
        "robots": runs["off"][0]["robots"],
        "fps": args.fps,
        "runs": args.runs,
        "wall_off": off,
        "wall_on": on,
        "walls_off": [r["wall"] for r in runs["off"]],
        "walls_on": [r["wall"] for r in runs["on"]],
        "overhead": overhead,
        "cpu_off": cpu_off,
        "cpu_on": cpu_on,
        "cpu_overhead": cpu_on / cpu_off - 1,
        "frames_decoded": [r["decoded"] for r in runs["on"]],
        **frame_cost(str(path)),
    }
    limit = STALLED_LIMIT if args.stalled else LIMIT
    watched = f"{args.stalled} stalled" if args.stalled else "1 viewer"
    summary["stalled"] = args.stalled
    print(
        f"{path.stem}: {summary['robots']} robots, virtual time; median of {args.runs} runs\n"
        f"  without --live   {off:8.2f} s\n"
        f"  --live, {watched:<8} {on:8.2f} s   ({overhead:+.1%}; target < {limit:.0%})\n"
        f"  CPU time (the run's process): {cpu_off:.2f} s without, {cpu_on:.2f} s with "
        f"({cpu_on / cpu_off - 1:+.1%})\n"
        + (
            f"  time in the view's sampled(), where frames are built and sent: "
            f"{[round(r['view_s'], 3) for r in runs['on']]} s\n"
            if args.stalled
            else ""
        )
        + f"  frames decoded   {summary['frames_decoded']} (at most {args.fps:g} a second)\n"
        f"  one frame        {summary['bytes']} bytes, built in {summary['build_us']:.0f} µs"
    )
    print(json.dumps(summary))
    completed = all(r["status"] == "completed" for mode in runs.values() for r in mode)
    return 0 if completed and overhead < limit else 1


if __name__ == "__main__":
    sys.exit(main())
