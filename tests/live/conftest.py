from __future__ import annotations

from pathlib import Path

import pytest

from .helpers import FIRE, cli, finish


@pytest.fixture(scope="session")
def fire_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished virtual run of the 25-robot Fire Brigade (with exchange snapshots)."""
    out = tmp_path_factory.mktemp("fire_run")
    with cli("run", FIRE / "thesis_5_8_2.toml", "--virtual", "--no-plots", "--out", out) as process:
        code, _, stderr = finish(process)
    assert code == 0, stderr
    return out
