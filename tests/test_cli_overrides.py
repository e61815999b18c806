"""``--set`` beside the flags that set the same keys: validated as the file is, never dropped.

A flag (``--seed``, ``--time-factor``, ``--virtual``, ``--transport``) sets its key
over the file's value; a ``--set`` of the same key must agree with it, or both are
refused. Each case is refused before anything is built: in process, milliseconds.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Final

import pytest

from cas_async._cli._main import main
from cas_async._cli._parser import overrides_of, parser

ROOT: Final = Path(__file__).resolve().parents[1]
SCENARIO: Final = ROOT / "apps" / "fire_brigade" / "scenarios" / "thesis_5_8_1.toml"


@pytest.mark.parametrize(
    ("args", "says"),
    [
        pytest.param(
            ["--set", "run.transport=nan", "--virtual"],
            'run.transport: expected one of "udp", "memory", "zenoh", got nan',
            id="transport-nan-virtual",
        ),
        pytest.param(
            ["--set", "run.transport=true", "--virtual"],
            'run.transport: expected one of "udp", "memory", "zenoh", got true',
            id="transport-true-virtual",
        ),
        pytest.param(
            ["--set", "run.transport=udp", "--virtual"],
            "run.transport: virtual time needs the memory transport",
            id="transport-udp-virtual",
        ),
        pytest.param(
            ["--set", "run.seed=abc", "--seed", "3", "--virtual"],
            "run.seed: --set 'run.seed=abc' contradicts --seed 3",
            id="seed",
        ),
        pytest.param(
            ["--set", "run.virtual=nan", "--time-factor", "200"],
            "run.virtual: --set 'run.virtual=nan' contradicts --time-factor 200",
            id="virtual-nan-time-factor",
        ),
        pytest.param(
            ["--set", "run.time_factor=-1", "--time-factor", "200"],
            "run.time_factor: --set 'run.time_factor=-1' contradicts --time-factor 200",
            id="time-factor",
        ),
        pytest.param(
            ["--set", "run.virtual=false", "--virtual"],
            "run.virtual: --set 'run.virtual=false' contradicts --virtual",
            id="virtual-false-virtual",
        ),
        pytest.param(
            ["--set", "run.transport=memory", "--transport", "udp"],
            "run.transport: --set 'run.transport=memory' contradicts --transport udp",
            id="transport",
        ),
    ],
)
def test_a_set_that_a_flag_would_hide_is_validated_or_refused(
    args: list[str], says: str, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    stdout, stderr = io.StringIO(), io.StringIO()
    code = main(["run", str(SCENARIO), *args, "--out", str(out)], stdout=stdout, stderr=stderr)
    assert code == 2
    (line,) = stderr.getvalue().splitlines()  # one line, no traceback
    assert line.startswith(f"error: {SCENARIO}: {says}"), line
    assert stdout.getvalue() == ""
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        pytest.param(
            ["--seed", "3", "--set", "run.seed=3"], ["run.seed=3", "run.seed=3"], id="agree"
        ),
        pytest.param(
            ["--time-factor", "200", "--set", "run.time_factor=200"],
            ["run.time_factor=200", "run.time_factor=200.0", "run.virtual=false"],
            id="an-int-for-a-float",
        ),
        pytest.param(
            ["--virtual"], ["run.virtual=true", 'run.transport="memory"'], id="virtual-memory"
        ),
        pytest.param(
            ["--virtual", "--set", "run.transport=zenoh"],
            ["run.transport=zenoh", "run.virtual=true"],
            id="a-named-transport-replaces-virtual's-default",
        ),
    ],
)
def test_flags_that_agree_with_a_set_pass_and_come_last(
    args: list[str], expected: list[str]
) -> None:
    assert overrides_of(parser().parse_args(["run", "x.toml", *args])) == expected
