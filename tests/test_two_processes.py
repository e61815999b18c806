"""Two robots in two OS processes, talking UDP on 127.0.0.1."""

from __future__ import annotations

import asyncio
import os
import sys
from pathlib import Path

from cas_async import Robot, UdpTransport
from tests.stacks import STACK_MESSAGES, Note, Query, Recorder

ROOT = Path(__file__).resolve().parent.parent


async def test_two_robots_in_two_processes() -> None:
    transport = UdpTransport()
    stack = [Recorder(), Recorder()]
    async with Robot(1, stack, transport=transport, messages=STACK_MESSAGES) as robot:
        _, port = robot.address  # type: ignore[misc]
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        peer = await asyncio.create_subprocess_exec(
            sys.executable,
            "-m",
            "tests.udp_peer",
            str(port),
            cwd=ROOT,
            env=env,
            stdout=asyncio.subprocess.PIPE,
        )
        try:
            assert peer.stdout is not None
            line = await asyncio.wait_for(peer.stdout.readline(), 20)
            transport.directory.add(2, "127.0.0.1", int(line))
            async with asyncio.timeout(20):
                while not stack[0].external:
                    await asyncio.sleep(0.005)
            hello = stack[0].external[0]
            assert (hello.text, hello.hops, hello.robot_id) == (
                "hello from another process",
                [2],
                2,
            )
            answer = await stack[0].request(2, Query(20), timeout=10)
            assert (answer.value, answer.robot_id) == (40, 2)
            stack[0].send(2, Note("bye", []))
            assert await asyncio.wait_for(peer.wait(), 20) == 0
        finally:
            if peer.returncode is None:
                peer.kill()
                await peer.wait()
