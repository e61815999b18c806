"""Messages sent are counted by class, internal and external, per robot and per swarm."""

from __future__ import annotations

from cas_async import Layer, MemoryTransport, Robot, Swarm
from cas_async.testing import wait_all_tasks_blocked
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, Recorder


class Asker(Recorder):
    """On start: one note down two levels, one query to robot 2, one broadcast note."""

    async def inner_process(self) -> None:
        await super().inner_process()
        if self.robot_id == 1 and self.inner_calls == 1:
            self.send_to_layer(2, Note("down", []))
            await self.request(2, Query(4))
            self.broadcast(Note("all", []))


async def test_counts_by_class_internal_and_external(cas_memory: MemoryTransport) -> None:
    def stack() -> list[Layer]:
        return [Asker(), Recorder(), Recorder()]

    swarm = Swarm(
        Robot(i, stack(), transport=cas_memory, messages=STACK_MESSAGES) for i in (1, 2, 3)
    )
    async with swarm:
        await wait_all_tasks_blocked()
        one = swarm[1].message_counts()
        two = swarm[2].message_counts()
        total = swarm.message_counts()
    # The note to level 2 passes level 1: it is sent once and forwarded, not counted twice.
    assert one == {"internal": {"Note": 1}, "external": {"Query": 1, "Note": 2}}
    assert two == {"internal": {}, "external": {"Answer": 1}}
    assert total == {"internal": {"Note": 1}, "external": {"Query": 1, "Note": 2, "Answer": 1}}
    assert sum(one["external"].values()) == swarm[1].counters()["sent_external"]
    assert Answer.__name__ in total["external"]
