"""Shared fixtures (robots that start and stop themselves), and the slow tests' time limit."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Sequence
from typing import Any, Final

import pytest

from cas_async import Layer, Robot, Transport
from cas_async.scenario.output import _plots as plots
from cas_async.testing import Robots
from tests.stacks import STACK_MESSAGES

SLOW_TIMEOUT: Final = 300
"""Wall seconds a test marked ``slow`` may take (the others: ``timeout`` in pyproject.toml, 60).

A slow test does seconds of real work (subprocesses, mypy, whole runs): 30-45 s on a
2-core machine beside a CPU hog, more than 60 s at a load of 8, where the one-minute
limit, meant to catch a hang, failed seven of them. A test that sets its own limit
keeps it.
"""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Gives each test marked ``slow`` without a ``timeout`` of its own :data:`SLOW_TIMEOUT`."""
    for item in items:
        if item.get_closest_marker("slow") and item.get_closest_marker("timeout") is None:
            item.add_marker(pytest.mark.timeout(SLOW_TIMEOUT))


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
