"""A run directory as untrusted input: every way a crafted one is wrong, refused in one line.

``view`` and ``export`` read a directory as a server reads a request (see
``cas_async.live._run_files``): each variant of :mod:`.crafted_runs` opens as a
:class:`RecordingError` naming the file, and the line and field where there is one,
before anything is served or written. A FIFO, a device or a link out of the
directory is refused without being read (they used to hang, or read until memory
ran out), hence the short time-out.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from cas_async.live import Recording, RecordingError

from .crafted_runs import VARIANTS, Damage
from .helpers import cli, finish


def _crafted(fire_run: Path, tmp_path: Path, damage: Damage) -> Path:
    run = tmp_path / "run"
    shutil.copytree(fire_run, run)
    damage(run)
    return run


@pytest.mark.timeout(10)
@pytest.mark.parametrize(("damage", "message"), list(VARIANTS.values()), ids=list(VARIANTS))
def test_a_crafted_run_directory_is_refused_naming_file_line_and_field(
    fire_run: Path, tmp_path: Path, damage: Damage, message: str
) -> None:
    run = _crafted(fire_run, tmp_path, damage)
    with pytest.raises(RecordingError) as refused:
        Recording(run)
    text = str(refused.value)
    assert "\n" not in text
    assert re.match(rf"{re.escape(str(run))}/{message}", text), text


def test_a_link_inside_the_run_directory_is_followed(fire_run: Path, tmp_path: Path) -> None:
    run = _crafted(fire_run, tmp_path, lambda run: (run / "trace.csv").rename(run / "kept.csv"))
    (run / "trace.csv").symlink_to("kept.csv")
    assert len(Recording(run)) == len(Recording(fire_run))


@pytest.mark.parametrize("command", ["view", "export"])
def test_view_and_export_refuse_a_crafted_directory_in_one_line_and_write_nothing(
    fire_run: Path, tmp_path: Path, command: str
) -> None:
    if command == "export":  # without the extra it refuses before reading the directory
        pytest.importorskip("mcap", reason="export --format mcap needs the mcap extra")
        pytest.importorskip("mcap_ros2", reason="export --format mcap needs the mcap extra")
    damage, _ = VARIANTS["t-nan"]
    run = _crafted(fire_run, tmp_path, damage)
    before = sorted(path.name for path in run.iterdir())
    extra = ["--port", "0"] if command == "view" else ["--format", "mcap"]
    with cli(command, run, *extra) as process:
        code, stdout, stderr = finish(process)
    assert code == 2
    assert stderr.splitlines() == [
        f"error: {run}/trace.csv: line 27: t: expected a number from 0 to 1e+09, got 'nan'"
    ]
    assert stdout == ""
    assert sorted(path.name for path in run.iterdir()) == before  # no run.mcap, no temporary
