"""A robot in its own process on Zenoh, for tests/test_zenoh_transport.py.

Usage: ``python -m tests.zenoh_peer MODE NAMESPACE ENDPOINT ROBOT_ID``: robot
``ROBOT_ID`` opens a ZenohTransport under ``NAMESPACE`` connected to ``ENDPOINT``
(where the test's session listens), prints ``open`` once its token is declared and
``closed`` once its robot and session are closed. Either way it gives up after 20 s,
so a broken test never leaves it behind.

* ``talk``: greets robot 1 until robot 1 answers, answers its queries (tests.stacks
  ``Recorder``), and stops when robot 1 says "bye".
* ``linger``: answers nothing and waits to be killed.
"""

from __future__ import annotations

import asyncio
import contextlib
import sys

import cas_async
from cas_async import Layer, Message, Robot, ZenohTransport
from tests.stacks import STACK_MESSAGES, Note, Recorder

LIFETIME = 20.0
"""Seconds before the peer gives up on its own."""


class Greeter(Recorder):
    """Says hello to robot 1 until robot 1 says anything; stops the robot on "bye"."""

    def __init__(self) -> None:
        super().__init__()
        self.expected = sys.maxsize  # run until robot 1 says "bye"

    async def inner_process(self) -> None:
        await super().inner_process()
        if not self.external:
            if self.knows(1):
                self.send(1, Note("hello from another process", [self.robot_id]))
            self.wake_after(0.05)

    async def handle_msg(self, msg: Message) -> None:
        await super().handle_msg(msg)  # answers Query NEGOTIATIONs
        if isinstance(msg, Note) and msg.text == "bye":
            self.robot.stop()


class Mute(Layer):
    """Hears everything, answers nothing."""


async def main(mode: str, namespace: str, endpoint: str, robot_id: int) -> None:
    transport = ZenohTransport(namespace=namespace, connect=[endpoint])
    layers: list[Layer] = [Greeter(), Recorder()] if mode == "talk" else [Mute(), Mute()]
    robot = Robot(robot_id, layers, transport=transport, messages=STACK_MESSAGES)
    try:
        async with robot:
            print("open", flush=True)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(robot.run(), LIFETIME)
    finally:
        transport.close()
    print("closed" if transport.session is None else "session left open", flush=True)


if __name__ == "__main__":
    mode, namespace, endpoint, robot_id = sys.argv[1:]
    cas_async.run(main(mode, namespace, endpoint, int(robot_id)))
