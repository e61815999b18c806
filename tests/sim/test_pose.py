"""Poses and the heading convention: radians, counter-clockwise from +x, in (-pi, pi]."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from cas_async import Pose, SimulationError
from cas_async.sim import normalize_angle

PI = math.pi


@pytest.mark.parametrize(
    ("angle", "expected"),
    [
        (0.0, 0.0),
        (PI, PI),
        (-PI, PI),
        (3 * PI, PI),
        (-PI / 2, -PI / 2),
        (2 * PI, 0.0),
        (5 * PI / 2, PI / 2),
    ],
    ids=["zero", "pi", "minus-pi-folds-to-pi", "three-pi", "minus-half-pi", "full-turn", "2.5pi"],
)
def test_normalize_angle(angle: float, expected: float) -> None:
    assert normalize_angle(angle) == pytest.approx(expected, abs=1e-12)


@given(st.floats(min_value=-1e6, max_value=1e6))
def test_normalized_angles_are_in_range_and_equivalent(angle: float) -> None:
    wrapped = normalize_angle(angle)
    assert -PI < wrapped <= PI
    assert math.cos(wrapped) == pytest.approx(math.cos(angle), abs=1e-9)
    assert math.sin(wrapped) == pytest.approx(math.sin(angle), abs=1e-9)


def test_pose_normalises_heading_and_coerces_numpy_scalars() -> None:
    pose = Pose(np.float64(1.5), np.int64(2), 3 * PI)  # type: ignore[arg-type]
    assert pose == Pose(1.5, 2.0, PI)
    assert type(pose.x) is float
    assert type(pose.y) is float


def bits(value: float) -> bytes:
    return struct.pack("<d", value)  # tells -0.0 from 0.0


def reference(x: float, y: float, heading: float) -> tuple[bytes, bytes, bytes] | str:
    """What a pose holds, by the book: floats, finite, the heading normalised (or the error)."""
    for name, value in (("x", x), ("y", y), ("heading", heading)):
        if not math.isfinite(float(value)):
            return f"{name} must be a finite number"
    return bits(float(x)), bits(float(y)), bits(normalize_angle(float(heading)))


@given(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(allow_nan=True, allow_infinity=True),
    st.one_of(st.floats(), st.sampled_from([PI, -PI, -0.0, math.nextafter(-PI, 0), 3 * PI])),
    st.sampled_from([float, np.float64]),
)
def test_a_pose_holds_its_values_by_the_book_to_the_bit(
    x: float, y: float, heading: float, kind: type
) -> None:
    # Poses whose values are floats already in range skip the coercion: same bits.
    expected = reference(x, y, heading)
    if isinstance(expected, str):
        with pytest.raises(SimulationError, match=f"^{expected}"):
            Pose(kind(x), y, heading)
        return
    pose = Pose(kind(x), y, kind(heading))
    assert (bits(pose.x), bits(pose.y), bits(pose.heading)) == expected
    assert type(pose.x) is type(pose.heading) is float


def test_minus_pi_is_folded_onto_pi() -> None:
    assert bits(Pose(0.0, 0.0, -PI).heading) == bits(PI)


def test_pose_is_frozen() -> None:
    pose = Pose(0, 0)
    with pytest.raises(AttributeError):
        pose.x = 1  # type: ignore[misc]


def test_distance_and_bearing() -> None:
    pose = Pose(1, 1, 0.3)
    assert pose.distance_to(4, 5) == 5.0
    assert pose.bearing_to(1, 5) == pytest.approx(PI / 2)
    assert pose.bearing_to(0, 1) == PI
    assert pose.bearing_to(1, 1) == 0.3  # same point: the heading is kept


@pytest.mark.parametrize(
    ("args", "name"),
    [
        ((math.nan, 0.0, 0.0), "x"),
        ((0.0, math.inf, 0.0), "y"),
        ((0.0, 0.0, math.nan), "heading"),
        ((0.0, 0.0, -math.inf), "heading"),
    ],
    ids=["nan-x", "inf-y", "nan-heading", "inf-heading"],
)
def test_non_finite_pose_is_refused_naming_the_field(
    args: tuple[float, float, float], name: str
) -> None:
    with pytest.raises(SimulationError, match=f"^{name} must be a finite number"):
        Pose(*args)


def test_simulation_error_is_a_value_error_and_a_cas_error() -> None:
    from cas_async import CasError

    with pytest.raises(ValueError, match="finite"):
        normalize_angle(math.nan)
    assert issubclass(SimulationError, CasError)
