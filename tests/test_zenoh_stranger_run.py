"""A shipped scenario on ``--transport zenoh`` while a stranger forges every robot's token.

The run is ``python -m cas_async run`` in a subprocess, on scaled time. The stranger,
in this process, finds where the run's Zenoh session listens (as anyone on the
machine can: ``/proc``), connects with a session of its own, watches the robots'
tokens come and declares, round after round, a token for each of them at a session
that does not exist (held for a second, then let go), and with a key a copy of each
real token moved to that session too. Before membership could not be forged, one
such round made a robot unreachable for the rest of the run (thousands of
``unknown_robot`` drops, makespan three to five times longer). Now the run completes
about as fast as a clean one, and the refusals are in its ``results.json``.

Scaled time is not reproducible: clean makespans of this scenario at a time factor
of 10 spread over about 22-31 s on a loaded 2-core machine. So clean and attacked
runs alternate, twice each, and their medians are compared.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import statistics
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

from tests.zenoh_support import until

zenoh = pytest.importorskip("zenoh")

pytestmark = [
    pytest.mark.slow,
    pytest.mark.timeout(400),
    pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="finds the port in /proc"),
]

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "apps/fire_brigade/scenarios/thesis_5_8_2.toml"
FAKE = "0123456789abcdef" * 2  # a session that does not exist
SIGNED = re.compile(r"(?P<head>.+/alive/\d+/)(?P<zid>[0-9a-f]+)(?P<tail>/\d+/[0-9a-f]{32})")
RUN_LIMIT = 120.0
"""Wall seconds a run may take (a clean one takes 3-8 s): a run that lost its robots
would go on to max_time, an hour of simulated time."""


def listening_ports(pid: int) -> list[int]:
    """The loopback TCP ports process ``pid`` listens on (Linux)."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            link = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:  # closed meanwhile
            continue
        if link.startswith("socket:["):
            inodes.add(link[len("socket:[") : -1])
    ports = []
    with open("/proc/net/tcp") as table:
        next(table)
        for line in table:
            fields = line.split()
            local, state, inode = fields[1], fields[3], fields[9]
            if state == "0A" and inode in inodes and local.startswith("0100007F:"):
                ports.append(int(local.split(":")[1], 16))
    return ports


def forge(endpoint: str, done: threading.Event, keyed: bool) -> int:
    """The stranger (blocking): forges tokens, round after round, until ``done``; rounds made."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([endpoint]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    seen: set[str] = set()
    lock = threading.Lock()

    def heard(sample: Any) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            with lock:
                seen.add(str(sample.key_expr))

    subscriber = session.liveliness().declare_subscriber("cas_async/alive/**", heard, history=True)
    rounds = 0
    try:
        while not done.is_set():
            with lock:
                real = sorted(key for key in seen if FAKE not in key)
            keys = {f"cas_async/alive/{key.split('/')[2]}/{FAKE}" for key in real}
            if keyed:
                keys |= {
                    f"{match['head']}{FAKE}{match['tail']}"
                    for match in map(SIGNED.fullmatch, real)
                    if match is not None
                }
            if not keys:
                done.wait(0.01)
                continue
            tokens = [session.liveliness().declare_token(key) for key in sorted(keys)]
            done.wait(1.0)  # held, then let go
            for token in tokens:
                token.undeclare()
            rounds += 1
            done.wait(0.2)
    finally:
        subscriber.undeclare()
        session.close()
    return rounds


async def run(out: Path, key_file: Path | None, *, attacked: bool) -> dict[str, Any]:
    """One run of the scenario on Zenoh at a time factor of 10; its results.json."""
    command = [sys.executable, "-m", "cas_async", "run", str(SCENARIO), "--transport", "zenoh"]
    command += ["--time-factor", "10", "--no-plots", "--out", str(out)]
    if key_file is not None:
        command += ["--key-file", str(key_file)]
    env = {key: value for key, value in os.environ.items() if key != "CAS_ASYNC_SWARM_KEY"}
    process = await asyncio.create_subprocess_exec(
        *command,
        cwd=ROOT,
        env=env,
        stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.PIPE,
    )
    done = threading.Event()
    stranger: asyncio.Future[int] | None = None
    try:
        if attacked:
            await until(lambda: listening_ports(process.pid), "the run's session", timeout=30)
            (port,) = listening_ports(process.pid)
            stranger = asyncio.ensure_future(
                asyncio.to_thread(forge, f"tcp/127.0.0.1:{port}", done, key_file is not None)
            )
        _, err = await asyncio.wait_for(process.communicate(), RUN_LIMIT)
    finally:
        done.set()
        if process.returncode is None:
            process.kill()
            await process.wait()
        rounds = 0 if stranger is None else await asyncio.wait_for(stranger, 30)
    assert process.returncode == 0, err.decode()[-3000:]
    assert rounds >= (1 if attacked else 0)
    results: dict[str, Any] = json.loads((out / "results.json").read_text())
    return results


@pytest.mark.parametrize("keyed", [False, True], ids=["no key", "key"])
async def test_a_run_with_a_stranger_forging_tokens_completes_about_as_fast(
    tmp_path: Path, keyed: bool
) -> None:
    key_file = None
    if keyed:
        key_file = tmp_path / "swarm.key"
        key_file.write_text("ab" * 32 + "\n")
        key_file.chmod(0o600)
    clean, attacked = [], []
    for n in range(2):
        clean.append(await run(tmp_path / f"clean{n}", key_file, attacked=False))
        attacked.append(await run(tmp_path / f"attacked{n}", key_file, attacked=True))
    for results in clean + attacked:
        assert results["status"] == "completed"
        assert "unknown_robot" not in results["protocol_errors"]
    for results in attacked:
        refused = results["protocol_errors"]
        if keyed:  # 25 robots, at least one round: unsigned, and moved to another session
            assert refused["transport.token_unsigned"] >= 25, refused
            assert refused["transport.token_forged"] >= 25, refused
        else:
            assert refused["transport.token_conflict"] >= 25, refused
    for results in clean:
        assert not [r for r in results["protocol_errors"] if r.startswith("transport.token")]
    makespans = [statistics.median(r["makespan"] for r in runs) for runs in (clean, attacked)]
    assert makespans[1] <= 1.2 * makespans[0], makespans
