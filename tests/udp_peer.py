"""Robot 2 in its own process, for tests/test_two_processes.py.

Usage: ``python -m tests.udp_peer PARENT_PORT``. Binds an OS-assigned port on
127.0.0.1 and prints it, greets robot 1 until it hears from it, answers its queries,
and exits when robot 1 says "bye" (or after 20 s, so a broken test never leaves it
behind).
"""

from __future__ import annotations

import asyncio
import sys

import cas_async
from cas_async import Message, Robot, UdpDirectory, UdpTransport
from tests.stacks import STACK_MESSAGES, Note, Recorder


class Peer(Recorder):
    def __init__(self) -> None:
        super().__init__()
        self.expected = sys.maxsize  # run until robot 1 says "bye"

    async def inner_process(self) -> None:
        await super().inner_process()
        # Greet until robot 1 answers: it refuses datagrams from robot 2 (unknown_source)
        # until it has read this process's port and entered it in its directory.
        if not self.external:
            self.send(1, Note("hello from another process", [2]))
            self.wake_after(0.05)

    async def handle_msg(self, msg: Message) -> None:
        await super().handle_msg(msg)  # answers Query NEGOTIATIONs
        if isinstance(msg, Note) and msg.text == "bye":
            self.robot.stop()


async def main(parent_port: int) -> None:
    transport = UdpTransport(UdpDirectory({1: ("127.0.0.1", parent_port)}))
    robot = Robot(2, [Peer(), Recorder()], transport=transport, messages=STACK_MESSAGES)
    async with robot:
        print(robot.address[1], flush=True)  # type: ignore[index]
        await asyncio.wait_for(robot.run(), 20)


if __name__ == "__main__":
    cas_async.run(main(int(sys.argv[1])))
