"""Both ready environments pass PettingZoo's own API tests: parallel, and AEC once converted."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

pytest.importorskip("pettingzoo")

from pettingzoo.test import api_test, parallel_api_test
from pettingzoo.utils.conversions import parallel_to_aec

from examples.rl.fire_brigade.env import make_env as fire_brigade
from examples.rl.gathering.env import make_env as gathering


@pytest.mark.parametrize("factory", [gathering, fire_brigade], ids=["gathering", "fire_brigade"])
def test_the_environment_passes_pettingzoo_s_parallel_api_test(
    factory: Callable[..., Any], make: Callable[..., Any], capsys: pytest.CaptureFixture[str]
) -> None:
    env = make(factory, overrides=["run.max_time=15"])
    parallel_api_test(env, num_cycles=1000)
    assert "Passed Parallel API test" in capsys.readouterr().out


@pytest.mark.parametrize("factory", [gathering, fire_brigade], ids=["gathering", "fire_brigade"])
def test_the_environment_passes_the_aec_api_test_through_pettingzoo_s_conversion(
    factory: Callable[..., Any], make: Callable[..., Any], capsys: pytest.CaptureFixture[str]
) -> None:
    env = make(factory, overrides=["run.max_time=10"])
    api_test(parallel_to_aec(env), num_cycles=300)
    assert "Passed API test" in capsys.readouterr().out
