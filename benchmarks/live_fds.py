"""The view's server when a burst of connections exhausts the process's open-file limit.

Not part of ``python -m benchmarks``::

    python -m benchmarks.live_fds [--mode view|virtual|scaled] [--limit 256] [--burst 1000]

The server runs in a child process whose ``RLIMIT_NOFILE`` is ``--limit``
(``resource.setrlimit`` before it starts): ``view`` of a run directory (asyncio's
loop), or ``run --live 0 --live-wait`` on virtual time (the VirtualTimeLoop) or on
scaled time (uvloop). Then:

1. **idle**: ``--idle`` connections that send nothing; how many the server still
   holds after the request time-out and a sweep (10 + 1 s);
2. **burst**: ``--burst`` connections opened as fast as they go (past the limit)
   and held for ``--hold`` seconds: the bytes the server wrote to stderr, and the
   CPU it used (a share of one core, from ``/proc``), over the burst and the hold;
3. **after**: every connection closed; a new viewer (a WebSocket client) must get
   the hello within 15 s, and a ``--live-wait`` run must then start and complete.

Reported as text and as one JSON line. Exit 1 when a target fails: stderr at most
64 KB, CPU at most half a core, the viewer answered, the run completed.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import resource
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Final

ROOT: Final = Path(__file__).resolve().parent.parent
SCENARIO: Final = ROOT / "apps" / "fire_brigade" / "scenarios" / "thesis_5_8_2.toml"
STDERR_LIMIT: Final = 64 * 1024
CPU_LIMIT: Final = 0.5
_BURST_LIMIT: Final = 45.0
"""Wall seconds the burst's connections may take to open (the rest count as failed)."""
_URL: Final = re.compile(r"http://[^/\s]+:(\d+)/")


def _cpu(pid: int) -> float:
    """CPU seconds (user and system) that process ``pid`` has used."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _limited(limit: int) -> Any:
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (limit, limit))

    return apply


def _command(mode: str, work: Path) -> list[str]:
    python = [sys.executable, "-m", "cas_async"]
    if mode == "view":
        run = work / "run"
        done = subprocess.run(
            [*python, "run", str(SCENARIO), "--virtual", "--no-plots", "--out", str(run)],
            cwd=ROOT,
            capture_output=True,
            check=False,
        )
        if done.returncode != 0:
            raise RuntimeError(f"the run to view failed: {done.stderr.decode()[-500:]}")
        return [*python, "view", str(run), "--port", "0"]
    timing = ["--virtual"] if mode == "virtual" else ["--time-factor", "20"]
    return [
        *python, "run", str(SCENARIO), *timing, "--transport", "memory", "--no-plots",
        "--out", str(work / "live"), "--live", "0", "--live-wait",
    ]  # fmt: skip


def _still_open(sock: socket.socket) -> bool:
    sock.setblocking(False)
    try:
        return sock.recv(1) != b""  # an answer (408) or nothing yet: see the end below
    except BlockingIOError:
        return True
    except OSError:
        return False


def _closed_by_server(sock: socket.socket) -> bool:
    """Whether the server answered and closed (or reset) a connection."""
    sock.setblocking(False)
    try:
        data = sock.recv(65536)
    except BlockingIOError:
        return False
    except OSError:
        return True
    while data:
        try:
            data = sock.recv(65536)
        except BlockingIOError:
            return False
        except OSError:
            return True
    return True


async def _viewer(port: int, limit: float, *, to_the_end: bool) -> bool:
    import websockets

    async with asyncio.timeout(limit), websockets.connect(f"ws://127.0.0.1:{port}/ws") as ws:
        hello = json.loads(await ws.recv())
        if to_the_end:  # a live run's frames, until its end closes the connection
            async for _ in ws:
                pass
    return bool(hello.get("type") == "hello")


def measure(
    mode: str, limit: int, idle: int, burst: int, hold: float, idle_wait: float = 11.5
) -> dict[str, Any]:
    """One measurement (see the module docs); its figures."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, min(hard, idle + burst + 256)), hard))
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        err_path = work / "stderr.txt"
        env = {**os.environ, "CAS_ASYNC_UVLOOP": "1" if mode == "scaled" else "0"}
        with err_path.open("wb") as err:
            process = subprocess.Popen(
                _command(mode, work),
                cwd=ROOT,
                env=env,
                stdout=subprocess.PIPE,
                stderr=err,
                text=True,
                preexec_fn=_limited(limit),
            )
        figures: dict[str, Any] = {"mode": mode, "limit": limit, "idle": idle, "burst": burst}
        held: list[socket.socket] = []
        try:
            assert process.stdout is not None
            match = _URL.search(process.stdout.readline())
            if match is None:
                raise RuntimeError(f"no address printed; stderr: {err_path.read_text()[-500:]}")
            port = int(match.group(1))
            # 1. idle connections
            quiet = [socket.create_connection(("127.0.0.1", port)) for _ in range(idle)]
            time.sleep(idle_wait)
            figures["idle_closed"] = sum(_closed_by_server(sock) for sock in quiet)
            for sock in quiet:
                sock.close()
            # 2. the burst
            before = err_path.stat().st_size
            cpu, began = _cpu(process.pid), time.monotonic()
            refused = 0
            for _ in range(burst):
                if time.monotonic() - began > _BURST_LIMIT:  # a server that stopped accepting
                    refused += 1
                    continue
                try:
                    held.append(socket.create_connection(("127.0.0.1", port), timeout=1.0))
                except OSError:
                    refused += 1
            figures["burst_s"] = time.monotonic() - began
            time.sleep(hold)
            elapsed = time.monotonic() - began
            figures["connected"], figures["connect_failed"] = len(held), refused
            figures["cpu_share"] = (_cpu(process.pid) - cpu) / elapsed
            figures["window_s"] = elapsed
            text = err_path.read_bytes()[before:]
            figures["stderr_bytes"] = len(text)
            figures["stderr_lines"] = text.decode(errors="replace").splitlines()[:6]
            figures["tracebacks"] = text.count(b"Traceback")
            # 3. afterwards
            for sock in held:
                sock.close()
            held = []
            began = time.monotonic()
            try:
                figures["viewer_answered"] = asyncio.run(
                    _viewer(port, 60.0, to_the_end=mode != "view")
                )
            except (OSError, TimeoutError, ValueError) as exc:
                figures["viewer_answered"] = False
                figures["viewer_error"] = repr(exc)
            figures["viewer_s"] = time.monotonic() - began
            if mode != "view":
                try:
                    process.wait(timeout=60)
                except subprocess.TimeoutExpired:
                    process.kill()
                figures["run_exit"] = process.returncode
        finally:
            for sock in held:
                sock.close()
            if process.poll() is None:
                process.terminate()
                try:
                    process.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
            if process.stdout is not None:
                process.stdout.close()
        figures["stderr_total_bytes"] = err_path.stat().st_size
    figures["ok"] = (
        figures["stderr_bytes"] <= STDERR_LIMIT
        and figures["cpu_share"] <= CPU_LIMIT
        and figures["viewer_answered"]
        and figures.get("run_exit", 0) == 0
    )
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.live_fds", description=__doc__)
    parser.add_argument("--mode", choices=("view", "virtual", "scaled"), default="virtual")
    parser.add_argument("--limit", type=int, default=256, help="the server's RLIMIT_NOFILE")
    parser.add_argument("--idle", type=int, default=100, help="idle connections first")
    parser.add_argument("--burst", type=int, default=1000, help="connections in the burst")
    parser.add_argument("--hold", type=float, default=5.0, help="seconds the burst is held")
    args = parser.parse_args(argv)
    figures = measure(args.mode, args.limit, args.idle, args.burst, args.hold)
    print(
        f"{args.mode}: open-file limit {args.limit}\n"
        f"  idle: {figures['idle_closed']}/{args.idle} idle connections closed by the server "
        f"after 11.5 s\n"
        f"  burst: {figures['connected']} of {args.burst} connected in "
        f"{figures['burst_s']:.1f} s ({figures['connect_failed']} failed), held "
        f"{args.hold:g} s: stderr {figures['stderr_bytes']:,} bytes "
        f"({figures['tracebacks']} tracebacks), CPU {figures['cpu_share']:.1%} of a core over "
        f"{figures['window_s']:.1f} s\n"
        f"  after: a new viewer answered {figures['viewer_answered']} "
        f"in {figures['viewer_s']:.1f} s; run exit {figures.get('run_exit', '-')}"
    )
    for line in figures["stderr_lines"]:
        print(f"  stderr: {line[:150]}")
    print(json.dumps(figures))
    return 0 if figures["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
