"""Shared fixtures: robots that start and stop themselves."""

from __future__ import annotations

from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import AsyncExitStack
from typing import Any

import pytest

from cas_async import Layer, MemoryTransport, Robot, Transport
from cas_async.scenario import _plots as plots
from tests.stacks import STACK_MESSAGES


@pytest.fixture
async def start_robot() -> AsyncIterator[Callable[..., object]]:
    """Factory: ``robot = await start_robot(robot_id, layers, ...)``; stopped at teardown."""
    async with AsyncExitStack() as stack:

        async def start(
            robot_id: int,
            layers: Sequence[Layer],
            *,
            transport: Transport | None = None,
            **kwargs: object,
        ) -> Robot:
            kwargs.setdefault("messages", STACK_MESSAGES)
            robot = Robot(robot_id, layers, transport=transport, **kwargs)  # type: ignore[arg-type]
            return await stack.enter_async_context(robot)

        yield start


@pytest.fixture
def memory() -> MemoryTransport:
    return MemoryTransport()


@pytest.fixture
def plot_notes(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The texts of the notes the figures draw instead of an empty panel, in order."""
    notes: list[str] = []
    draw = plots._note

    def recording_note(axes: Any, text: str) -> None:
        notes.append(text)
        draw(axes, text)

    monkeypatch.setattr(plots, "_note", recording_note)
    return notes
