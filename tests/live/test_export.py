"""``export RUN_DIR --format mcap``: a ROS 2 bag that the mcap reader and decoder read back."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cas_async.live import export_mcap

from .helpers import cli, finish, read_trace, results_of

pytest.importorskip("mcap_ros2")

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


def test_the_bag_holds_a_pose_array_per_sample_equal_to_the_trace(
    fire_run: Path, tmp_path: Path
) -> None:
    out = tmp_path / "run.mcap"
    with cli("export", fire_run, "--format", "mcap", "--out", out) as process:
        code, stdout, stderr = finish(process)
    assert code == 0, stderr
    trace = read_trace(fire_run / "trace.csv")
    assert f"({len(trace.times)} samples)" in stdout
    results = results_of(fire_run)
    messages: dict[str, list[tuple[int, object]]] = {}
    with out.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            messages.setdefault(channel.topic, []).append((message.log_time, decoded))
            assert channel.message_encoding == "cdr"
            assert schema.encoding == "ros2msg"
    robots = messages["/robots"]
    assert len(robots) == len(trace.times)
    for (log_time, poses), t, xy in zip(robots, trace.times, trace.xy, strict=True):
        assert log_time == round(t * 1e9)
        assert poses.header.frame_id == "world"
        assert poses.header.stamp.sec + poses.header.stamp.nanosec / 1e9 == pytest.approx(t)
        got = np.array([[pose.position.x, pose.position.y] for pose in poses.poses])
        assert np.array_equal(got, xy)  # float64 all the way: exactly the trace's
    for name, ids in results["groups"].items():
        topic = messages[f"/robots/{name.lower()}"]
        assert len(topic) == len(trace.times)
        assert all(len(poses.poses) == len(ids) for _, poses in topic)
    carriers = messages["/carriers"]
    assert [len(p.poses) for _, p in carriers] == [int(c.sum()) for c in trace.carrying]
    line_share = [decoded.data for _, decoded in messages["/measures/line_share"]]
    assert line_share == results["series"]["line_share"]["value"]
    ((_, scene),) = messages["/scene"]
    kinds = {marker.type for marker in scene.markers}
    assert kinds == {3, 4, 9}  # cylinders (stations' areas), line strips, text labels
    stations = [m for m in scene.markers if m.type == 3]
    assert len(stations) == 4
    assert all(math.isclose(m.scale.x, 2.0) for m in stations)  # radius 1: the area of a station


def test_a_directory_that_is_no_run_is_refused_naming_the_file(tmp_path: Path) -> None:
    with cli("export", tmp_path, "--format", "mcap") as process:
        code, _, stderr = finish(process)
    assert code == 2
    assert f"{tmp_path / 'results.json'}: missing" in stderr
    assert not (tmp_path / "run.mcap").exists()


def _schemas(path: Path) -> dict[str, bytes]:
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    return {schema.name: schema.data for schema in summary.schemas.values()}


def test_the_schemas_are_named_as_rosbag2_names_them(fire_run: Path, tmp_path: Path) -> None:
    """``geometry_msgs/msg/PoseArray``, as a bag that rosbag2 (here rosbags' writer) records."""
    out = tmp_path / "run.mcap"
    export_mcap(fire_run, out)
    ours = _schemas(out)
    assert set(ours) == {
        "geometry_msgs/msg/PoseArray",
        "std_msgs/msg/Float64",
        "visualization_msgs/msg/MarkerArray",
    }
    rosbag2 = pytest.importorskip("rosbags.rosbag2")
    typesys = pytest.importorskip("rosbags.typesys")
    store = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    with rosbag2.Writer(
        tmp_path / "bag", version=9, storage_plugin=rosbag2.StoragePlugin.MCAP
    ) as writer:
        for k, name in enumerate(sorted(ours)):
            writer.add_connection(f"/topic{k}", name, typestore=store)
    (recorded,) = (tmp_path / "bag").glob("*.mcap")
    assert set(_schemas(recorded)) == set(ours)
    for name, definition in ours.items():  # and rosbags reads our definitions by that name
        types = typesys.get_types_from_msg(definition.decode(), name)
        assert name in types
