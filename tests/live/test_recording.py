"""A run directory read back: the replay's and the export's source, and its errors."""

from __future__ import annotations

import asyncio
import json
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest

from cas_async.live import UNKNOWN, Recording, RecordingError

from .helpers import cli, finish, read_trace, results_of, url_of


def test_every_sample_reads_back_as_the_trace_has_it(fire_run: Path) -> None:
    recording = Recording(fire_run)
    trace = read_trace(fire_run / "trace.csv")
    results = results_of(fire_run)
    assert recording.robots == trace.robots
    assert recording.times == trace.times
    assert recording.world == (10.0, 10.0)
    assert len(recording.scene.shapes) == 6  # two lines, four stations
    assert [count for _, count in recording.exchanges] == list(range(1, results["exchanges"] + 1))
    for k in (0, 7, len(recording) - 1):
        sample = recording.sample(k)
        assert np.array_equal(sample.xy, trace.xy[k])
        assert np.array_equal(sample.carrying, trace.carrying[k])
        assert sample.done == sum(t <= sample.t for t in results["delivery_times"])
        assert sample.measures == (results["series"]["line_share"]["value"][k],)
    last = recording.sample(len(recording) - 1)
    assert last.detail == max(n for t, n in recording.exchanges if t <= last.t)
    assert recording.index_at(-1.0) == 0
    assert recording.index_at(7.5) == 7
    with pytest.raises(IndexError):
        recording.sample(len(recording))


def _copy(fire_run: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(fire_run, copy)
    return copy


def test_a_run_without_scene_json_replays_without_a_scene(fire_run: Path, tmp_path: Path) -> None:
    copy = _copy(fire_run, tmp_path)
    (copy / "scene.json").unlink()
    recording = Recording(copy)
    assert recording.scene.shapes == ()
    assert recording.world == (10.0, 10.0)  # from the scenario as results.json keeps it


def test_without_exchange_snapshots_the_second_count_is_unknown(
    fire_run: Path, tmp_path: Path
) -> None:
    copy = _copy(fire_run, tmp_path)
    lines = (copy / "trace.csv").read_text().splitlines(keepends=True)
    kept = [lines[0], *(line for line in lines[1:] if line.split(",")[4] == "")]
    (copy / "trace.csv").write_text("".join(kept))
    assert Recording(copy).sample(3).detail == UNKNOWN


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda d: (d / "results.json").unlink(), "results.json: missing"),
        (lambda d: (d / "trace.csv").unlink(), "trace.csv: missing"),
        (lambda d: (d / "results.json").write_text("{"), "results.json: not JSON: Expecting"),
        (lambda d: (d / "trace.csv").write_text("a,b\n"), "trace.csv: line 1: expected the header"),
        (
            lambda d: (d / "scene.json").write_text(json.dumps({"format": "other"})),
            "scene.json: format: expected 'cas_async scene'",
        ),
        (
            lambda d: (d / "trace.csv").write_text(
                (d / "trace.csv").read_text().replace("\n0.0,1,", "\n0.0,1,4.0\n", 1)
            ),
            "trace.csv: line 2: expected 6 fields",
        ),
    ],
    ids=["no-results", "no-trace", "bad-json", "bad-header", "scene-format", "short-row"],
)
def test_a_run_directory_that_cannot_be_replayed_is_refused_naming_the_file(
    fire_run: Path,
    tmp_path: Path,
    damage,
    message: str,  # type: ignore[no-untyped-def]
) -> None:
    copy = _copy(fire_run, tmp_path)
    damage(copy)
    with pytest.raises(RecordingError, match=message):
        Recording(copy)


def test_a_row_of_the_wrong_robot_is_named_when_opened(fire_run: Path, tmp_path: Path) -> None:
    copy = _copy(fire_run, tmp_path)
    text = (copy / "trace.csv").read_text()
    lines = text.splitlines(keepends=True)
    row = lines.index(next(line for line in lines if line.startswith("1.0,5,") and ",," in line))
    fields = lines[row].split(",")
    fields[1] = "999"
    lines[row] = ",".join(fields)
    (copy / "trace.csv").write_text("".join(lines))
    with pytest.raises(
        RecordingError, match=f"trace.csv: line {row + 1}: robot: expected robot 5's row, got 999"
    ):
        Recording(copy)


def test_view_refuses_a_directory_that_is_no_run(tmp_path: Path) -> None:
    with cli("view", tmp_path, "--port", "0") as process:
        code, _, stderr = finish(process)
    assert code == 2
    assert f"{tmp_path / 'results.json'}: missing" in stderr


def test_view_serves_until_a_signal(fire_run: Path) -> None:
    pytest.importorskip("websockets")
    with cli("view", fire_run, "--port", "0") as process:
        url = url_of(process, "replay:")
        seen = asyncio.run(_hello(url))
        process.send_signal(signal.SIGTERM)
        code, _, stderr = finish(process)
    assert seen["mode"] == "replay"
    assert code == 0
    assert "replay stopped" in stderr


async def _hello(url: str) -> dict[str, object]:
    import websockets

    async with websockets.connect(url.replace("http://", "ws://") + "ws") as socket:
        data: dict[str, object] = json.loads(await socket.recv())
        return data
