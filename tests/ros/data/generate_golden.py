"""Makes the golden CDR of tests/ros: a Twist and an Odometry serialized by real rclpy.

Not run by the test suite (it needs rclpy, which cas_async does not depend on). It
was run once, from the repository root, in a throwaway virtual environment outside
the worktree, with ROS 2 Kilted's rclpy from pip wheels (no ROS install):

    python3.11 -m venv /tmp/rclpy-venv
    /tmp/rclpy-venv/bin/pip install ros-kilted-rclpy ros-kilted-geometry-msgs \
        ros-kilted-nav-msgs ros-kilted-rmw-fastrtps-cpp
    /tmp/rclpy-venv/bin/python tests/ros/data/generate_golden.py

(ros-kilted-rclpy 9.1.2, ros-kilted-geometry-msgs 5.5.1, ros-kilted-nav-msgs 5.5.1,
ros-kilted-rmw-fastrtps-cpp 9.3.3.) It writes, beside itself, ``twist.cdr`` and
``odometry.cdr`` (the bytes ``rclpy.serialization.serialize_message`` returns:
the 4-byte encapsulation header and little-endian CDR, as rmw_zenoh puts them on
the wire) and ``golden.json``: the values serialized, and the rclpy versions.
Twist and Odometry have the same definitions, and type hashes, in Jazzy and Kilted.
"""

from __future__ import annotations

import json
import math
from importlib import metadata
from pathlib import Path

from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message

HERE = Path(__file__).resolve().parent

TWIST = {"linear": {"x": 0.5, "y": -0.125, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": -0.25}}
YAW = 0.6
ODOMETRY = {
    "header": {"stamp": {"sec": 1700000000, "nanosec": 123456789}, "frame_id": "odom"},
    "child_frame_id": "base_footprint",
    "pose": {
        "pose": {
            "position": {"x": 1.5, "y": -2.25, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(YAW / 2), "w": math.cos(YAW / 2)},
        },
        "covariance": [0.01 * (i + 1) if i % 7 == 0 else 0.0 for i in range(36)],
    },
    "twist": {
        "twist": {
            "linear": {"x": 0.4, "y": 0.0, "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": 0.1},
        },
        "covariance": [0.002 * (i + 1) if i % 7 == 0 else 0.0 for i in range(36)],
    },
}


def _vector(target: object, values: dict[str, float]) -> None:
    for name, value in values.items():
        setattr(target, name, value)


def main() -> None:
    twist = Twist()
    _vector(twist.linear, TWIST["linear"])
    _vector(twist.angular, TWIST["angular"])
    odometry = Odometry()
    odometry.header.stamp.sec = ODOMETRY["header"]["stamp"]["sec"]
    odometry.header.stamp.nanosec = ODOMETRY["header"]["stamp"]["nanosec"]
    odometry.header.frame_id = ODOMETRY["header"]["frame_id"]
    odometry.child_frame_id = ODOMETRY["child_frame_id"]
    pose = ODOMETRY["pose"]
    _vector(odometry.pose.pose.position, pose["pose"]["position"])
    _vector(odometry.pose.pose.orientation, pose["pose"]["orientation"])
    odometry.pose.covariance = pose["covariance"]
    moving = ODOMETRY["twist"]
    _vector(odometry.twist.twist.linear, moving["twist"]["linear"])
    _vector(odometry.twist.twist.angular, moving["twist"]["angular"])
    odometry.twist.covariance = moving["covariance"]
    (HERE / "twist.cdr").write_bytes(serialize_message(twist))
    (HERE / "odometry.cdr").write_bytes(serialize_message(odometry))
    versions = {
        name: metadata.version(name)
        for name in (
            "ros-kilted-rclpy",
            "ros-kilted-geometry-msgs",
            "ros-kilted-nav-msgs",
            "ros-kilted-rmw-fastrtps-cpp",
        )
    }
    golden = {"twist": TWIST, "odometry": ODOMETRY, "made_with": versions}
    (HERE / "golden.json").write_text(json.dumps(golden, indent=2) + "\n")
    print(f"wrote twist.cdr, odometry.cdr and golden.json in {HERE}")


if __name__ == "__main__":
    main()
