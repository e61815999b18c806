"""Shared fixtures: robots that start and stop themselves."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Sequence
from typing import Any

import pytest

from cas_async import Layer, Robot, Transport
from cas_async.scenario.output import _plots as plots
from cas_async.testing import Robots
from tests.stacks import STACK_MESSAGES


@pytest.fixture
def start_robot(cas_robots: Robots) -> Callable[..., Awaitable[Robot]]:
    """``robot = await start_robot(robot_id, layers, ...)``: the plugin's ``cas_robots.start``.

    With this suite's test stack (``tests.stacks``) by default. The plugin stops the
    robots at teardown and fails a test whose robots dropped messages it did not
    allow (``cas_robots.allowed_drops``).
    """

    async def start(
        robot_id: int, layers: Sequence[Layer], *, transport: Transport | None = None, **kwargs: Any
    ) -> Robot:
        kwargs.setdefault("messages", STACK_MESSAGES)
        return await cas_robots.start(robot_id, layers, transport=transport, **kwargs)

    return start


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
