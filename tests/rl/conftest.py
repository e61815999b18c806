"""Environments for the rl tests, closed after each test (the extra's tests skip without it)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest


@pytest.fixture
def make() -> Iterator[Callable[..., Any]]:
    """``env = make(factory, **kwargs)``: an env from ``factory``, closed when the test ends."""
    made: list[Any] = []

    def build(factory: Callable[..., Any], **kwargs: Any) -> Any:
        env = factory(**kwargs)
        made.append(env)
        return env

    yield build
    for env in made:
        env.close()
