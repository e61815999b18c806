"""The ROS 2 message definitions an MCAP export carries (the ``.msg`` text ROS 2 itself uses).

An MCAP file of the ``ros2`` profile holds each channel's schema as the message's
definition followed by every type it uses, each after a line of ``=`` and
``MSG: package/Type``: tools (Foxglove, Lichtblick, ``ros2 bag``, Rerun) decode
the CDR messages from it with no ROS installation. The definitions below are
ROS 2 Humble's, which later releases read too.
"""

from __future__ import annotations

from typing import Final

__all__ = ["DEFINITIONS"]

_SEPARATOR: Final = "=" * 80

_TYPES: Final = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec",
    "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "std_msgs/ColorRGBA": "float32 r\nfloat32 g\nfloat32 b\nfloat32 a",
    "std_msgs/Float64": "float64 data",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation",
    "geometry_msgs/PoseArray": "std_msgs/Header header\ngeometry_msgs/Pose[] poses",
    "visualization_msgs/Marker": "\n".join(
        [
            *(
                f"int32 {name}={value}"
                for name, value in (
                    ("ARROW", 0),
                    ("CUBE", 1),
                    ("SPHERE", 2),
                    ("CYLINDER", 3),
                    ("LINE_STRIP", 4),
                    ("LINE_LIST", 5),
                    ("CUBE_LIST", 6),
                    ("SPHERE_LIST", 7),
                    ("POINTS", 8),
                    ("TEXT_VIEW_FACING", 9),
                    ("MESH_RESOURCE", 10),
                    ("TRIANGLE_LIST", 11),
                    ("ADD", 0),
                    ("MODIFY", 0),
                    ("DELETE", 2),
                    ("DELETEALL", 3),
                )
            ),
            "std_msgs/Header header",
            "string ns",
            "int32 id",
            "int32 type",
            "int32 action",
            "geometry_msgs/Pose pose",
            "geometry_msgs/Vector3 scale",
            "std_msgs/ColorRGBA color",
            "builtin_interfaces/Duration lifetime",
            "bool frame_locked",
            "geometry_msgs/Point[] points",
            "std_msgs/ColorRGBA[] colors",
            "string text",
            "string mesh_resource",
            "bool mesh_use_embedded_materials",
        ]
    ),
    "visualization_msgs/MarkerArray": "visualization_msgs/Marker[] markers",
}

_USES: Final = {
    "std_msgs/Float64": (),
    "geometry_msgs/PoseArray": (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
    ),
    "visualization_msgs/MarkerArray": (
        "visualization_msgs/Marker",
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
        "geometry_msgs/Vector3",
        "std_msgs/ColorRGBA",
        "builtin_interfaces/Duration",
    ),
}


def _definition(datatype: str) -> str:
    parts = [_TYPES[datatype]]
    for used in _USES[datatype]:
        parts += [_SEPARATOR, f"MSG: {used}", _TYPES[used]]
    return "\n".join(parts) + "\n"


DEFINITIONS: Final = {datatype: _definition(datatype) for datatype in _USES}
"""The full definition of each message type written, by ROS 2 name."""
