"""The Strategy layer's answers to partnership requests follow what the robot holds."""

from __future__ import annotations

import cas_async
from apps.fire_brigade import MESSAGES, TimeStrategy
from apps.fire_brigade.messages import Destination, Exchanged, Kind, RequestPartner
from cas_async import Layer, MemoryTransport, Message, MsgType, Robot, Swarm, VirtualClock
from tests.fire_brigade.test_strategies import params


class Asker(Layer):
    """Asks robot 1 for a partnership and keeps the answer."""

    def __init__(self) -> None:
        self.answers: list[Message] = []

    async def handle_msg(self, msg: Message) -> None:
        self.answers.append(msg)


def _ask(target: int, asker: Asker) -> None:
    request = RequestPartner(
        1.0,
        1.0,
        Kind.TRANSPORTER,
        bucket=9,
        to=Destination(3, 5.0, 19.0),
        msg_type=MsgType.NEGOTIATION,
    )
    asker.send(target, request)


def test_a_transporter_that_just_received_a_bucket_refuses_partners() -> None:
    """Between Exchanged going up and MoveBucket coming down, the robot holds a bucket."""

    async def main() -> list[MsgType]:
        transport, clock = MemoryTransport(), VirtualClock()
        strategy, asker = TimeStrategy(params(peers=())), Asker()
        robots = [
            Robot(1, [strategy], transport=transport, clock=clock, messages=MESSAGES),
            Robot(2, [asker], transport=transport, clock=clock, messages=MESSAGES),
        ]
        async with Swarm(robots):
            _ask(1, asker)  # idle: accepted
            await clock.sleep(1)
            # the first partnership completes, and this robot now holds the bucket
            exchanged = Exchanged(
                partner=2, bucket=9, has_bucket=True, x=1.0, y=1.0, to=Destination(3, 5.0, 19.0)
            )
            await strategy.store_intra_msg(exchanged)
            _ask(1, asker)
            await clock.sleep(1)
        return [answer.msg_type for answer in asker.answers]

    assert cas_async.run(main(), virtual=True) == [MsgType.ACCEPT, MsgType.DENY]
