"""The live view's protocol, end to end: ``run --live 127.0.0.1:0 --live-wait`` and a client.

The client is the ``websockets`` package (an implementation independent of the
server's): it decodes every frame, and each one must equal the ``trace.csv`` rows
of its instant exactly, since both come from the same sampler.
"""

from __future__ import annotations

import asyncio
import math
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from cas_async.live import UNKNOWN, decode_frame
from cas_async.live._protocol import encode_frame

from .helpers import BOXES, FIRE, cli, finish, read_trace, results_of, same_run, url_of, watch

pytest.importorskip("websockets")


def test_a_frame_decodes_to_what_was_encoded() -> None:
    xy = np.array([[0.1, 2.0], [1e-300, -3.5], [math.pi, 7.0]])
    carrying = np.array([True, False, True])
    data = encode_frame(12.5, 7, 3, UNKNOWN, [0.25, math.nan], xy, carrying, final=True)
    assert len(data) == 40 + 2 * 8 + 3 * 17
    frame = decode_frame(data)
    assert (frame.t, frame.seq, frame.done, frame.detail, frame.final) == (
        12.5,
        7,
        3,
        UNKNOWN,
        True,
    )
    assert frame.measures[0] == 0.25
    assert math.isnan(frame.measures[1])
    assert np.array_equal(frame.xy, xy)
    assert np.array_equal(frame.carrying, carrying)


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda data: data[:20], "shorter than its 40-byte header"),
        (lambda data: b"XXXX" + data[4:], "magic"),
        (lambda data: data + b"\0", "expected 91"),
    ],
    ids=["short", "magic", "length"],
)
def test_a_damaged_frame_is_refused_saying_why(damage, message: str) -> None:  # type: ignore[no-untyped-def]
    data = encode_frame(1.0, 0, 0, 0, [], np.zeros((3, 2)), np.zeros(3, dtype=bool))
    with pytest.raises(ValueError, match=message):
        decode_frame(damage(data))


def _check_against_trace(seen, out: Path) -> None:  # type: ignore[no-untyped-def]
    results = results_of(out)
    trace = read_trace(out / "trace.csv")
    hello = seen.hello
    assert hello["type"] == "hello"
    assert hello["protocol"] == 1
    assert hello["mode"] == "live"
    assert hello["robots"] == trace.robots
    grouped = sorted(robot for group in hello["groups"] for robot in group["robots"])
    assert grouped == sorted(trace.robots)
    assert {g["name"]: g["robots"] for g in hello["groups"]} == results["groups"]
    assert seen.frames, "no frame"
    times = [frame.t for frame in seen.frames]
    assert times == sorted(set(times)), "t must increase from frame to frame"
    seqs = [frame.seq for frame in seen.frames]
    assert seqs == sorted(set(seqs))
    for frame in seen.frames:
        k = trace.at(frame.t)  # a frame is a sample of the trace: its instant is a row's
        assert frame.seq == k
        assert len(frame.xy) == len(trace.robots)
        assert np.array_equal(frame.xy, trace.xy[k]), f"positions at t = {frame.t}"
        assert np.array_equal(frame.carrying, trace.carrying[k]), f"carriers at t = {frame.t}"
        assert 0 <= frame.done <= results["target"]
        assert len(frame.measures) == len(hello["measures"])
    assert seen.frames[-1].done <= results["delivered"]
    end = seen.end
    assert end is not None
    assert end["status"] == results["status"]
    assert end["makespan"] == results["makespan"]


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
def test_every_frame_is_the_trace_row_of_its_instant(tmp_path: Path) -> None:
    out = tmp_path / "run"
    scenario = FIRE / "thesis_5_8_2.toml"
    args = ("run", scenario, "--virtual", "--no-plots", "--out", out)
    with cli(*args, "--live", "127.0.0.1:0", "--live-wait", "--live-fps", "10000") as process:
        url = url_of(process, "live view:")
        assert not url.endswith(":0/"), "the printed address names the port picked"
        seen = asyncio.run(watch(url))
        code, _, stderr = finish(process)
    assert code == 0, stderr
    _check_against_trace(seen, out)
    trace = read_trace(out / "trace.csv")
    # A fast client misses no sample when frames may go as fast as they come.
    assert [frame.t for frame in seen.frames] == trace.times
    results = results_of(out)
    exchanges = [event for event in seen.events if event["type"] == "exchange"]
    delivered = [event for event in seen.events if event["type"] == "delivered"]
    assert [event["count"] for event in exchanges] == list(range(1, results["exchanges"] + 1))
    assert [event["t"] for event in delivered] == results["delivery_times"]
    assert all(event["from"] != event["to"] for event in exchanges)
    # the same run without a viewer: --live changes nothing it measures
    again = tmp_path / "again"
    with cli("run", scenario, "--virtual", "--no-plots", "--out", again) as process:
        assert finish(process)[0] == 0
    same_run(results_of(out), results_of(again))
    assert (again / "trace.csv").read_bytes() == (out / "trace.csv").read_bytes()


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
def test_a_run_on_scaled_time_is_watched_on_uvloop(tmp_path: Path) -> None:
    """``run --live`` without ``--virtual`` runs on uvloop, whose transports are its own."""
    pytest.importorskip("uvloop")
    out = tmp_path / "run"
    args = ("run", FIRE / "thesis_5_8_2.toml", "--time-factor", "20", "--transport", "memory")
    with cli(
        *args, "--no-plots", "--out", out, "--live", "0", "--live-wait",
        env={"CAS_ASYNC_UVLOOP": "1"},
    ) as process:  # fmt: skip
        seen = asyncio.run(watch(url_of(process, "live view:")))
        code, _, stderr = finish(process)
    assert code == 0, stderr
    assert "Traceback" not in stderr
    assert seen.hello["mode"] == "live"
    assert seen.frames
    _check_against_trace(seen, out)
    end = seen.end
    assert end is not None
    assert end["status"] == "completed"


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
def test_frames_are_capped_per_wall_second(tmp_path: Path) -> None:
    out = tmp_path / "run"
    args = ("run", FIRE / "thesis_5_8_2.toml", "--virtual", "--no-plots", "--out", out)
    fps = 4.0
    with cli(
        *args, "--live", "0", "--live-wait", "--live-fps", str(fps), "--live-pace", "40"
    ) as process:
        url = url_of(process, "live view:")
        began = time.monotonic()
        seen = asyncio.run(watch(url))
        elapsed = time.monotonic() - began  # spans every send: the run starts on connecting
        code, _, stderr = finish(process)
    assert code == 0, stderr
    _check_against_trace(seen, out)
    # Sends are at least 1/fps wall seconds apart (the last one too), so over the
    # connection's life there can be no more than this, however slow the machine:
    assert len(seen.frames) <= fps * elapsed + 1
    assert len(seen.frames) < len(read_trace(out / "trace.csv").times), "samples were skipped"


def test_box_moving_is_shown_with_its_scene_and_its_own_counts(tmp_path: Path) -> None:
    out = tmp_path / "run"
    args = ("run", BOXES / "thesis_4_4.toml", "--virtual", "--no-plots", "--out", out)
    with cli(*args, "--live", "127.0.0.1:0", "--live-wait", "--live-fps", "10000") as process:
        seen = asyncio.run(watch(url_of(process, "live view:")))
        code, _, stderr = finish(process)
    assert code == 0, stderr
    _check_against_trace(seen, out)
    shapes = seen.hello["scene"]["shapes"]
    objects = [shape for shape in shapes if shape["kind"] == "object"]
    assert len(objects) == results_of(out)["target"] + 2  # the thesis's seven objects, five to move
    assert {shape["shape"] for shape in shapes} == {"disc", "spot", "rect"}
    assert seen.hello["kind"] == "boxes"
    assert seen.hello["noun"] == "object"
    progress = [event for event in seen.events if event["type"] == "progress"]
    assert [event["done"] for event in progress][-1] == results_of(out)["delivered"]
    assert seen.frames[-1].detail != UNKNOWN


def test_a_signal_stops_a_run_waiting_for_its_viewer(tmp_path: Path) -> None:
    out = tmp_path / "run"
    args = ("run", FIRE / "thesis_5_8_2.toml", "--virtual", "--out", out)
    with cli(*args, "--live", "127.0.0.1:0", "--live-wait") as process:
        url_of(process, "live view:")
        assert process.stderr is not None
        assert "waiting for a viewer" in process.stderr.readline()
        time.sleep(0.2)  # waiting: nothing ran
        assert process.poll() is None
        process.send_signal(signal.SIGINT)
        code, _, _ = finish(process)
    assert code == 130
    assert results_of(out)["status"] == "interrupted"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--live-pace", "2"), "--live-pace and --live-wait need --live"),
        (("--live", "0", "--live-pace", "2", "--time-factor", "50"), "virtual time"),
        (("--live", "70000"), "port from 0 to 65535"),
        (("--live", "0", "--live-fps", "0"), "positive number"),
    ],
    ids=["pace-without-live", "pace-on-scaled-time", "bad-port", "bad-fps"],
)
def test_live_options_that_cannot_work_are_refused(
    args: tuple[str, ...], message: str, tmp_path: Path
) -> None:
    with cli(
        "run", FIRE / "thesis_5_8_2.toml", "--out", tmp_path / "o", "--no-plots", *args
    ) as process:
        code, _, stderr = finish(process)
    assert code == 2
    assert message in stderr


def test_a_busy_port_is_refused_naming_it(tmp_path: Path) -> None:
    import socket

    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        args = ("run", FIRE / "thesis_5_8_2.toml", "--virtual", "--out", tmp_path, "--no-plots")
        with cli(*args, "--live", f"127.0.0.1:{port}") as process:
            code, _, stderr = finish(process)
    assert code == 2
    assert f"--live 127.0.0.1:{port}" in stderr
    assert "in use" in stderr


@pytest.mark.slow
def test_across_processes_the_world_serves_the_view(tmp_path: Path) -> None:
    pytest.importorskip("zenoh")
    out = tmp_path / "run"
    args = ("run", FIRE / "thesis_5_8_2.toml", "--virtual", "--processes", "2", "--no-plots")
    with cli(
        *args, "--out", out, "--live", "127.0.0.1:0", "--live-wait", "--live-fps", "10000"
    ) as process:
        seen = asyncio.run(watch(url_of(process, "live view:")))
        code, _, stderr = finish(process)
    assert code == 0, stderr
    _check_against_trace(seen, out)
    assert len(seen.frames) == len(read_trace(out / "trace.csv").times)
    assert any(event["type"] == "exchange" for event in seen.events)
