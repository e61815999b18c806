"""Both ready environments pass PettingZoo's own test of the parallel API."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

pytest.importorskip("pettingzoo")

from pettingzoo.test import parallel_api_test

from examples.rl.fire_brigade.env import make_env as fire_brigade
from examples.rl.gathering.env import make_env as gathering


@pytest.mark.parametrize("factory", [gathering, fire_brigade], ids=["gathering", "fire_brigade"])
def test_the_environment_passes_pettingzoo_s_parallel_api_test(
    factory: Callable[..., Any], make: Callable[..., Any], capsys: pytest.CaptureFixture[str]
) -> None:
    env = make(factory, overrides=["run.max_time=15"])
    parallel_api_test(env, num_cycles=1000)
    assert "Passed Parallel API test" in capsys.readouterr().out
