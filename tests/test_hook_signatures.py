"""A layer's hooks are checked against Layer's when a robot is built: async where Layer's is, arity.

The runtime awaits ``handle_msg(msg)`` and calls ``termination_condition()`` without
awaiting: a hook of another shape would fail only when first called (a message,
late in a run) or never say so (a coroutine is always true). A robot refuses it
when it is built, naming the robot, the layer, the hook and Layer's signature.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Awaitable, Callable, Hashable
from typing import Any

import pytest

from cas_async import ConfigurationError, Layer, Message, Robot
from cas_async._core._hooks import Hooks, hook_problems


class NoMessage(Layer):
    async def handle_msg(self) -> None:  # type: ignore[override]
        pass


class TwoKeys(Layer):
    async def on_timer(self, key: Hashable, when: float) -> None:  # type: ignore[override]
        pass


class KeywordOnly(Layer):
    async def store_intra_msg(self, *, msg: Message) -> None:  # type: ignore[override]
        pass


class PlainInner(Layer):
    def inner_process(self) -> None:  # type: ignore[override]
        pass


class AsyncDone(Layer):
    async def termination_condition(self) -> bool:  # type: ignore[override]
        return True  # a coroutine: always true, had it been called


class AsyncReply(Layer):
    async def get_msg_reply(self, msg: Message) -> Message | None:  # type: ignore[override]
        return None


class NotAMethod(Layer):
    on_restart = None  # type: ignore[assignment]


REFUSED = [
    pytest.param(
        NoMessage,
        "handle_msg(self) -> None cannot be called as "
        "Layer's async def handle_msg(self, msg: Message) -> None",
        id="too-few-arguments",
    ),
    pytest.param(
        TwoKeys,
        "on_timer(self, key: Hashable, when: float) -> None cannot be called as "
        "Layer's async def on_timer(self, key: Hashable) -> None",
        id="too-many-arguments",
    ),
    pytest.param(
        KeywordOnly,
        "store_intra_msg(self, *, msg: Message) -> None cannot be called as "
        "Layer's async def store_intra_msg(self, msg: Message) -> None",
        id="keyword-only",
    ),
    pytest.param(
        PlainInner,
        "inner_process is a plain def, where Layer's is "
        "async def inner_process(self) -> None (the runtime awaits it)",
        id="plain-where-awaited",
    ),
    pytest.param(
        AsyncDone,
        "termination_condition is async def, where Layer's is "
        "def termination_condition(self) -> bool (the runtime does not await it)",
        id="async-condition",
    ),
    pytest.param(
        AsyncReply,
        "get_msg_reply is async def, where Layer's is "
        "def get_msg_reply(self, msg: Message) -> Message | None (the runtime does not await it)",
        id="async-reply",
    ),
    pytest.param(
        NotAMethod,
        "on_restart is None, not a method like "
        "Layer's async def on_restart(self, error: Exception) -> None",
        id="not-a-method",
    ),
]


@pytest.mark.parametrize(("cls", "problem"), REFUSED)
def test_a_robot_refuses_a_hook_it_could_not_call(cls: type[Layer], problem: str) -> None:
    assert hook_problems(cls) == (problem,)
    with pytest.raises(ConfigurationError) as refused:
        Robot(7, [Layer(), cls()])
    assert str(refused.value) == f"robot 7: {cls.__name__} at level 1: {problem}"


def test_every_problem_of_a_class_is_named_at_once() -> None:
    class Both(NoMessage, AsyncDone):
        pass

    with pytest.raises(ConfigurationError) as refused:
        Robot(1, [Both()])
    assert str(refused.value).count("; ") == 1
    assert "handle_msg(self)" in str(refused.value)
    assert "termination_condition is async def" in str(refused.value)


def _passing_through(hook: Callable[..., Awaitable[None]]) -> Callable[..., Awaitable[None]]:
    @functools.wraps(hook)
    def wrapper(*args: Any) -> Awaitable[None]:  # plain, but wraps an async def
        return hook(*args)

    return wrapper


class Flexible(Layer):
    """Hooks of other shapes that the runtime can call as it calls Layer's."""

    async def handle_msg(self, msg: Message, seen: int = 0) -> None:  # a default
        pass

    async def on_timer(self, *keys: Hashable) -> None:  # type: ignore[override]
        pass

    @staticmethod
    async def on_robot_joined(robot_id: int) -> None:
        pass

    @classmethod
    async def on_robot_left(cls, robot_id: int) -> None:
        pass

    @_passing_through
    async def store_intra_msg(self, msg: Message) -> None:
        pass

    def termination_condition(self) -> bool:
        return False

    def get_msg_reply(self, msg: Message) -> Message | None:
        return None


def test_hooks_the_runtime_can_call_pass() -> None:
    assert hook_problems(Layer) == ()
    assert hook_problems(Flexible) == ()
    Robot(1, [Flexible()])


def test_the_runtime_s_hooks_are_layer_s() -> None:
    hooks = [name for name, member in vars(Hooks).items() if inspect.isfunction(member)]
    for name in hooks:
        if name.startswith("_"):
            continue
        ours, layers = getattr(Hooks, name), getattr(Layer, name)
        assert inspect.signature(ours) == inspect.signature(layers), name
        assert inspect.iscoroutinefunction(ours) == inspect.iscoroutinefunction(layers), name
