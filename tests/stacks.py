"""Messages and layers shared by the runtime tests and the two-process peer script."""

from __future__ import annotations

from cas_async import Layer, Message, MsgType, message


@message
class Note(Message):
    """A plain payload; ``hops`` lets a test see which layer touched it."""

    text: str
    hops: list[int]


@message
class Query(Message):
    """Asked with request_* or as a NEGOTIATION; answered with Answer."""

    value: int


@message
class Answer(Message):
    value: int
    by_level: int


STACK_MESSAGES = (Note, Query, Answer)


class Recorder(Layer):
    """Records what reaches each hook; answers queries with value * 2 (or DENY if negative)."""

    def __init__(self) -> None:
        self.external: list[Message] = []
        self.internal: list[Message] = []
        self.negotiations: list[Message] = []
        self.inner_calls = 0
        self.expected = 0

    async def inner_process(self) -> None:
        self.inner_calls += 1

    async def handle_msg(self, msg: Message) -> None:
        self.external.append(msg)
        if msg.msg_type == MsgType.NEGOTIATION and isinstance(msg, Query):
            self.reply(msg, Answer(msg.value * 2, self.level))

    async def store_intra_msg(self, msg: Message) -> None:
        self.internal.append(msg)

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        self.negotiations.append(msg)
        if isinstance(msg, Query):
            answer = Answer(msg.value * 2, self.level)
            if msg.value < 0:
                answer.msg_type = MsgType.DENY
            return answer
        return None

    def termination_condition(self) -> bool:
        return len(self.external) + len(self.internal) >= self.expected


def recorders(count: int) -> list[Recorder]:
    """A stack of ``count`` recording layers."""
    return [Recorder() for _ in range(count)]
