"""A run directory as a ROS 2 bag in MCAP: ``export RUN_DIR --format mcap`` (the ``mcap`` extra).

The bag opens in Foxglove, Lichtblick, ``ros2 bag play`` and Rerun. Its topics,
all in frame ``world`` (x right, y up, z 0), stamped with simulated time (a
message at simulated second ``t`` has the timestamp ``t`` s after the epoch):

* ``/robots``: ``geometry_msgs/msg/PoseArray``, one per sample: every robot, in the
  trace's order (positions only: the trace holds no heading);
* ``/robots/<group>``: the same per group (``/robots/transporter``), so a tool
  can colour them by role; ``/carriers``: the robots carrying something;
* ``/measures/<name>``: ``std_msgs/msg/Float64``, one per sample of each measure;
* ``/scene``: ``visualization_msgs/msg/MarkerArray``, once at time 0: the world's
  bounds and the application's static scene (discs as cylinders, rectangles
  as cubes, lines as line strips, spots as spheres, labels as text).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, Final

from ..scenario import Disc, Polyline, Rect, Scene
from ..scenario.output import atomic_binary_file
from ._protocol import OTHER, colors_for
from ._recording import Recording
from ._ros2 import DEFINITIONS

__all__ = ["export_mcap", "schema_name"]

FRAME: Final = "world"
_POSES: Final = "geometry_msgs/PoseArray"
_NUMBER: Final = "std_msgs/Float64"
_MARKERS: Final = "visualization_msgs/MarkerArray"
_MARKER = {"CUBE": 1, "SPHERE": 2, "CYLINDER": 3, "LINE_STRIP": 4, "TEXT": 9}
_THIN: Final = 0.05  # height of flat shapes, width of lines, in world units


def _import_writer() -> Any:
    try:
        from mcap_ros2.writer import Writer
    except ImportError:
        raise ImportError(
            "export --format mcap needs the mcap extra: pip install 'cas_async[mcap]' "
            "(mcap and mcap-ros2-support)"
        ) from None
    return Writer


def export_mcap(run_dir: Path, out: Path) -> int:
    """Writes ``run_dir``'s recording to ``out`` as a ROS 2 bag (MCAP); returns the samples.

    Raises:
        RecordingError: the run directory cannot be read (naming the file).
        ImportError: the ``mcap`` extra is not installed (saying how to install it).
    """
    writer_type = _import_writer()
    recording = Recording(run_dir)
    groups = recording.groups
    rows = {robot: k for k, robot in enumerate(recording.robots)}
    topics = {
        f"/robots/{_slug(name)}": [rows[r] for r in ids if r in rows]
        for name, ids in groups.items()
    }
    with atomic_binary_file(Path(out)) as stream:  # whole or not at all
        writer = writer_type(stream)
        poses, number, markers = (
            writer.register_msgdef(schema_name(datatype), DEFINITIONS[datatype])
            for datatype in (_POSES, _NUMBER, _MARKERS)
        )
        colors = colors_for(list(groups), recording.scene)
        scene = _markers(recording.scene, recording.world, colors)
        writer.write_message("/scene", markers, {"markers": scene}, log_time=0, publish_time=0)
        for index in range(len(recording)):
            sample = recording.sample(index)
            when = round(sample.t * 1e9)
            header = {"stamp": _stamp(sample.t), "frame_id": FRAME}
            everyone = [_pose(x, y) for x, y in sample.xy.tolist()]
            chosen = {
                "/robots": everyone,
                **{topic: [everyone[k] for k in members] for topic, members in topics.items()},
                "/carriers": [
                    pose for pose, held in zip(everyone, sample.carrying, strict=True) if held
                ],
            }
            for topic, members in chosen.items():
                message = {"header": header, "poses": members}
                writer.write_message(topic, poses, message, when, when, sequence=index)
            for name, value in zip(recording.measures, sample.measures, strict=True):
                if math.isfinite(value):
                    topic = f"/measures/{_slug(name)}"
                    writer.write_message(topic, number, {"data": value}, when, when, sequence=index)
        writer.finish()
    return len(recording)


def schema_name(datatype: str) -> str:
    """A channel's schema name as rosbag2 writes it: ``geometry_msgs/msg/PoseArray``.

    The definitions' own ``MSG:`` lines keep the short form (``MSG: geometry_msgs/Pose``),
    as rosbag2's do.
    """
    package, _, name = datatype.partition("/")
    return f"{package}/msg/{name}"


def _slug(name: str) -> str:
    """A topic name's part: lower case, letters, digits and underscores."""
    return re.sub(r"[^a-z0-9_]+", "_", name.lower()).strip("_") or "unnamed"


def _stamp(t: float) -> dict[str, int]:
    nanoseconds = round(t * 1e9)  # t is from 0 to 1e9 (checked when read): int32 seconds
    return {"sec": nanoseconds // 1_000_000_000, "nanosec": nanoseconds % 1_000_000_000}


def _pose(x: float, y: float, angle: float = 0.0) -> dict[str, Any]:
    return {
        "position": {"x": x, "y": y, "z": 0.0},
        "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(angle / 2), "w": math.cos(angle / 2)},
    }


def _rgba(color: str, alpha: float) -> dict[str, float]:
    return {
        "r": int(color[1:3], 16) / 255,
        "g": int(color[3:5], 16) / 255,
        "b": int(color[5:7], 16) / 255,
        "a": alpha,
    }


def _markers(
    scene: Scene, world: tuple[float, float], colors: dict[str, str]
) -> list[dict[str, Any]]:
    """The world's bounds, then one marker per shape, then one per label."""
    width, height = world
    corners = [(0.0, 0.0), (width, 0.0), (width, height), (0.0, height), (0.0, 0.0)]
    out = [_marker("world", 0, "LINE_STRIP", _pose(0, 0), (_THIN, 0, 0), OTHER, points=corners)]
    for k, shape in enumerate(scene.shapes, start=1):
        color = colors.get(shape.kind, OTHER)
        if isinstance(shape, Disc):
            size = (2 * shape.radius, 2 * shape.radius, _THIN)
            out.append(_marker("scene", k, "CYLINDER", _pose(shape.x, shape.y), size, color, 0.35))
        elif isinstance(shape, Rect):
            size = (shape.width, shape.height, _THIN)
            where = _pose(shape.x, shape.y, shape.angle)
            out.append(_marker("scene", k, "CUBE", where, size, color, 0.6))
        elif isinstance(shape, Polyline):
            line = (_THIN, 0.0, 0.0)
            out.append(
                _marker("scene", k, "LINE_STRIP", _pose(0, 0), line, color, points=shape.points)
            )
        else:
            size = (4 * _THIN, 4 * _THIN, 4 * _THIN)
            out.append(_marker("scene", k, "SPHERE", _pose(shape.x, shape.y), size, color))
        if shape.label:
            x, y = shape.points[0] if isinstance(shape, Polyline) else (shape.x, shape.y)
            label = _marker("labels", k, "TEXT", _pose(x, y), (0, 0, 0.4), color, text=shape.label)
            out.append(label)
    return out


def _marker(
    ns: str,
    ident: int,
    kind: str,
    pose: dict[str, Any],
    scale: tuple[float, float, float],
    color: str,
    alpha: float = 1.0,
    *,
    points: Any = (),
    text: str = "",
) -> dict[str, Any]:
    return {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": FRAME},
        "ns": ns,
        "id": ident,
        "type": _MARKER[kind],
        "action": 0,
        "pose": pose,
        "scale": dict(zip("xyz", scale, strict=True)),
        "color": _rgba(color, alpha),
        "lifetime": {"sec": 0, "nanosec": 0},
        "frame_locked": False,
        "points": [{"x": x, "y": y, "z": 0.0} for x, y in points],
        "colors": [],
        "text": text,
        "mesh_resource": "",
        "mesh_use_embedded_materials": False,
    }
