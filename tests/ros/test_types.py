"""ROS message types: CDR equal to real rclpy's, hashes, plain values, clear errors.

The golden bytes in ``data/`` were serialized once by rclpy (ROS 2 Kilted, pip
wheels, no ROS install): ``data/generate_golden.py`` says how. Twist's bytes must
be equal; Odometry's differ from ours only in 5 padding bytes rclpy leaves
uninitialised, so its decoded values are compared (and ours re-decode the same).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("rosbags")

from cas_async import ConfigurationError, EncodeError
from cas_async.ros import DISTRO, DISTROS, TypeCatalog

DATA = Path(__file__).resolve().parent / "data"
GOLDEN: dict[str, Any] = json.loads((DATA / "golden.json").read_text())
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
ODOMETRY_HASH = "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"


@pytest.fixture(scope="module")
def types() -> TypeCatalog:
    return TypeCatalog(DISTRO)


def test_jazzy_is_the_pinned_distribution() -> None:
    assert DISTRO == "jazzy"
    assert DISTROS == ("jazzy", "kilted")


def test_twist_bytes_equal_rclpy_s(types: TypeCatalog) -> None:
    twist = types.get("geometry_msgs/msg/Twist")
    golden = (DATA / "twist.cdr").read_bytes()
    assert twist.encode(GOLDEN["twist"]) == golden
    assert twist.decode(golden) == GOLDEN["twist"]


def test_odometry_decodes_to_the_values_rclpy_serialized(types: TypeCatalog) -> None:
    odometry = types.get("nav_msgs/msg/Odometry")
    golden = (DATA / "odometry.cdr").read_bytes()
    assert odometry.decode(golden) == GOLDEN["odometry"]
    ours = odometry.encode(GOLDEN["odometry"])
    assert len(ours) == len(golden)
    assert odometry.decode(ours) == GOLDEN["odometry"]
    differing = sum(a != b for a, b in zip(ours, golden, strict=True))
    assert differing <= 5, "only rclpy's uninitialised padding may differ"


@pytest.mark.parametrize("distro", DISTROS)
@pytest.mark.parametrize(
    ("name", "type_hash"),
    [("geometry_msgs/msg/Twist", TWIST_HASH), ("nav_msgs/msg/Odometry", ODOMETRY_HASH)],
    ids=["Twist", "Odometry"],
)
def test_the_published_type_hashes(distro: str, name: str, type_hash: str) -> None:
    assert TypeCatalog(distro).get(name).type_hash == type_hash


def test_missing_fields_are_zero_and_the_short_name_works(types: TypeCatalog) -> None:
    twist = types.get("geometry_msgs/Twist")
    assert twist.name == "geometry_msgs/msg/Twist"
    assert twist.decode(twist.encode({"angular": {"z": 1}})) == {
        "linear": {"x": 0.0, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 1.0},
    }
    assert types.get("geometry_msgs/msg/Twist") is twist


def test_sequences_and_strings_round_trip(types: TypeCatalog) -> None:
    joints = types.get("sensor_msgs/msg/JointState")
    value = {"name": ["left", "right"], "position": [1.5, -2.0], "velocity": [], "effort": [0.25]}
    decoded = joints.decode(joints.encode(value))
    assert {key: decoded[key] for key in value} == value


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"linear": {"q": 1.0}}, r"Twist\.linear: no field 'q' in geometry_msgs/msg/Vector3"),
        ({"linear": {"x": "fast"}}, r"Twist\.linear\.x: expected a number \(float64\)"),
        ({"linear": {"x": True}}, r"Twist\.linear\.x: expected a number"),
        ({"linear": 3}, r"Twist\.linear: expected a mapping"),
        ({"speed": 1}, r"no field 'speed' in geometry_msgs/msg/Twist \(fields: linear, angular\)"),
    ],
    ids=["unknown-field", "string", "bool", "not-a-mapping", "top-level"],
)
def test_values_that_do_not_fit_say_which_field(
    types: TypeCatalog, value: dict[str, Any], message: str
) -> None:
    with pytest.raises(EncodeError, match=message):
        types.get("geometry_msgs/msg/Twist").encode(value)


def test_integers_are_checked_against_their_range(types: TypeCatalog) -> None:
    header = types.get("std_msgs/msg/Header")
    with pytest.raises(EncodeError, match=r"stamp\.nanosec: -1 is out of the range of uint32"):
        header.encode({"stamp": {"nanosec": -1}})
    covariance = types.get("geometry_msgs/msg/PoseWithCovariance")
    with pytest.raises(EncodeError, match=r"covariance: expected 36 items, got 2"):
        covariance.encode({"covariance": [0.0, 1.0]})


def test_an_unknown_type_is_refused_with_suggestions(types: TypeCatalog) -> None:
    with pytest.raises(
        ConfigurationError, match=r"unknown ROS message type .*Twst.* did you mean .*Twist"
    ):
        types.get("geometry_msgs/msg/Twst")


@pytest.mark.parametrize(
    ("distro", "why"),
    [("humble", "no type hashes"), ("rolling", "pin a release"), ("noetic", "no such ROS 2")],
)
def test_an_unsupported_distribution_is_refused_saying_why(distro: str, why: str) -> None:
    with pytest.raises(
        ConfigurationError, match=rf"{distro!r} is not supported \(.*{why}.*pinned to jazzy"
    ):
        TypeCatalog(distro)


@pytest.mark.parametrize(
    "data",
    [b"", b"\x00\x01\x00\x00", b"\x00\x01\x00\x00\xff\xff\xff\x7f", bytes(range(7))],
    ids=["empty", "header-only", "huge-length", "garbage"],
)
def test_malformed_cdr_raises_and_never_hangs(types: TypeCatalog, data: bytes) -> None:
    with pytest.raises(Exception):  # noqa: B017, PT011 - whatever rosbags raises; the link counts it
        types.get("nav_msgs/msg/Odometry").decode(data)
