"""Two robots play catch over UDP: the smallest complete cas_async program.

Each robot has three layers. The top layer (Play) throws a Ball to the other
robot's top layer; on receiving one, it asks its bottom layer (Motion) to catch it
with ``request_layer`` (forwarded through the middle layer), and throws it back.
Motion "moves" by sleeping the catch's duration on the robot's clock, so a time
factor of 20 makes a 1.5-simulated-second catch last 75 ms.

Run: ``python examples/two_robots.py [--throws N] [--time-factor X]``
"""

from __future__ import annotations

import argparse
import time

import cas_async
from cas_async import Layer, Message, Robot, ScaledClock, Swarm, UdpTransport


class Ball(Message):
    throw: int
    speed: float


class Catch(Message):
    speed: float


class Caught(Message):
    seconds: float


class Play(Layer):
    """Throws, catches (by asking Motion) and throws back until enough throws."""

    def __init__(self, throws: int, starts: bool) -> None:
        self.throws, self.starts, self.seen = throws, starts, 0

    async def inner_process(self) -> None:
        if self.starts:
            self.starts = False
            self.send(2, Ball(throw=1, speed=4.0))

    async def handle_msg(self, msg: Message) -> None:
        match msg:
            case Ball(throw=throw, speed=speed):
                self.seen = throw
                caught = await self.request_layer(2, Catch(speed), reply=Caught)
                print(
                    f"t={self.clock.now():6.2f}s robot {self.robot_id} caught throw {throw} "
                    f"in {caught.seconds:.2f}s"
                )
                if throw < self.throws:
                    self.send(msg.robot_id, Ball(throw=throw + 1, speed=speed * 1.1))
                else:
                    self.robot.stop()

    def termination_condition(self) -> bool:
        return self.seen >= self.throws - 1


class Relay(Layer):
    """The middle layer: forwarding between Play and Motion is automatic."""


class Motion(Layer):
    """The robotic layer: a catch takes 6 m / speed simulated seconds."""

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        match msg:
            case Catch(speed=speed):
                seconds = 6.0 / speed
                await self.clock.sleep(seconds)
                return Caught(seconds)
        return None


async def main(throws: int, time_factor: float) -> None:
    transport, clock = UdpTransport(), ScaledClock(time_factor)
    swarm = Swarm(
        Robot(
            rid,
            [Play(throws, starts=rid == 1), Relay(), Motion()],
            transport=transport,
            clock=clock,
        )
        for rid in (1, 2)
    )
    started = time.perf_counter()
    async with swarm:  # opens both endpoints before either robot starts
        await swarm.run()
    print(
        f"{throws} throws in {clock.now():.1f} simulated s, "
        f"{time.perf_counter() - started:.2f} s wall, time factor {time_factor:g}"
    )
    for robot in swarm:
        print(f"robot {robot.robot_id} at {robot.address}: {robot.counters()}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--throws", type=int, default=10)
    parser.add_argument("--time-factor", type=float, default=20.0)
    args = parser.parse_args()
    cas_async.run(main(args.throws, args.time_factor))
