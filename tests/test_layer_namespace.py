"""A layer's namespace is its author's: the runtime keeps one attribute, ``_cas``, in it."""

from __future__ import annotations

import math

import pytest

import cas_async
from cas_async import Layer, MemoryTransport, Message, Robot, Swarm, VirtualClock
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, Recorder

HOOKS = {
    "inner_process",
    "handle_msg",
    "store_intra_msg",
    "get_intra_msg_reply",
    "on_restart",
    "termination_condition",
}

# Everything the runtime used to keep in the layer, and the read-only views it offers.
STATE_NAMES = [
    "log",
    "clock",
    "robot",
    "robot_id",
    "level",
    "counters",
    "inbox",
    "requests",
    "timers",
    "_robot",
    "_level",
    "_above",
    "_below",
    "_live",
    "_log",
    "_counters",
    "_inbox",
    "_requests",
    "_wakes",
    "_congested",
    "_waiting_on",
]

# Every public name of Layer that is not a hook: methods too may be shadowed.
API_NAMES = sorted(name for name in dir(Layer) if not name.startswith("_") and name not in HOOKS)


def test_the_runtime_keeps_one_attribute_in_the_layer() -> None:
    layer = Layer()
    assert set(vars(layer)) == {"_cas"}
    Robot(1, [layer], messages=STACK_MESSAGES)
    assert set(vars(layer)) == {"_cas"}
    own = {name for name in vars(Layer) if name.startswith("_") and not name.startswith("__")}
    assert own == set()  # no private helper of the runtime in the class either


class Shadowing(Recorder):
    """A layer that names its own attributes like the runtime's state, and still talks."""

    def __init__(self, asks: bool) -> None:
        super().__init__()
        for name in STATE_NAMES:
            setattr(self, name, f"mine: {name}")
        self.asks = asks
        self.asked: list[int] = []

    async def handle_msg(self, msg: Message) -> None:
        self.external.append(msg)
        if isinstance(msg, Query):
            self.reply(msg, Answer(msg.value * 2, 0))

    async def inner_process(self) -> None:
        if self.asks and not self.asked:
            reply = await self.request(2, Query(3), timeout=1.0)
            assert isinstance(reply, Answer)
            self.asked.append(reply.value)
            self.send(2, Note("hello", []))
            self.send_down(Note("down", []))
            self.wake_after(1.0)


def test_a_layer_may_name_its_attributes_like_the_runtime_s_state() -> None:
    async def main() -> tuple[Shadowing, Shadowing, list[Recorder]]:
        clock, memory = VirtualClock(), MemoryTransport()
        one, two = Shadowing(asks=True), Shadowing(asks=False)
        below = [Recorder(), Recorder()]
        robots = [
            Robot(robot_id, [top, bottom], transport=memory, clock=clock, messages=STACK_MESSAGES)
            for robot_id, top, bottom in ((1, one, below[0]), (2, two, below[1]))
        ]
        async with Swarm(robots):
            await clock.sleep(2.0)
            counted = robots[0].counters()
        assert counted["sent_external"] == 2  # the request and the note
        return one, two, below

    one, two, below = cas_async.run(main(), virtual=True)
    assert one.asked == [6]
    assert [m.text for m in two.external if isinstance(m, Note)] == ["hello"]
    assert [m.text for m in below[0].internal] == ["down"]
    for layer in (one, two):
        assert all(getattr(layer, name) == f"mine: {name}" for name in STATE_NAMES)


class Silent(Layer):
    """Shadows every public name but the hooks; the runtime still drives its hooks."""

    def __init__(self) -> None:
        for name in API_NAMES:
            setattr(self, name, f"mine: {name}")
        self.external: list[Message] = []
        self.stored: list[Message] = []

    async def handle_msg(self, msg: Message) -> None:
        self.external.append(msg)

    async def store_intra_msg(self, msg: Message) -> None:
        self.stored.append(msg)

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        assert isinstance(msg, Query)
        return Answer(msg.value * 2, msg.value)

    def termination_condition(self) -> bool:
        return len(self.external) == 1 and len(self.stored) == 1


@pytest.mark.parametrize("shadowed", [API_NAMES], ids=["every-public-name"])
def test_a_layer_may_shadow_the_messaging_api_itself(shadowed: list[str]) -> None:
    async def main() -> tuple[Silent, int]:
        clock, memory = VirtualClock(), MemoryTransport()
        silent, talker, other = Silent(), Recorder(), Recorder()
        robots = [
            Robot(1, [silent, talker], transport=memory, clock=clock, messages=STACK_MESSAGES),
            Robot(2, [other, Recorder()], transport=memory, clock=clock, messages=STACK_MESSAGES),
        ]
        async with Swarm(robots):
            answer = await talker.request_up(Query(5), timeout=math.inf)
            talker.send_up(Note("up", []))
            other.send(1, Note("over", []))
            await robots[0].run()  # until Silent's termination condition holds
        assert isinstance(answer, Answer)
        return silent, answer.value

    silent, value = cas_async.run(main(), virtual=True)
    assert value == 10
    assert [m.text for m in silent.external if isinstance(m, Note)] == ["over"]
    assert all(getattr(silent, name) == f"mine: {name}" for name in shadowed)
