"""Transforms τ: Euler round trips, composition and inverse, orthonormality, gimbal lock, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.geometry import (
    Transform,
    check_pose,
    compose,
    euler_from_rotation,
    invert_pose,
    rotation_from_euler,
)

from .strategies import angle_diff, pitch, poses, roll_yaw, transforms


@settings(deadline=None)
@given(transforms(max_pitch=89.0))
def test_transform_matrix_transform_round_trip(tau):
    back = Transform.from_matrix(tau.matrix())
    for name in ("roll", "pitch", "yaw"):
        assert angle_diff(getattr(back, name), getattr(tau, name)) < 1e-9, f"{name}: {tau} -> {back}"
    np.testing.assert_allclose(back.translation, tau.translation, atol=1e-12)


@settings(deadline=None)
@given(transforms())
def test_euler_of_any_rotation_rebuilds_it_and_is_canonical(tau):
    """Even at and near gimbal lock the extracted angles rebuild the same rotation, in canonical ranges."""
    roll, p, yaw = euler_from_rotation(tau.rotation)
    assert -180.0 < roll <= 180.0 and -90.0 <= p <= 90.0 and -180.0 < yaw <= 180.0, (roll, p, yaw)
    err = np.abs(rotation_from_euler(roll, p, yaw) - tau.rotation).max()
    assert err < 1e-12, f"{tau}: angles {(roll, p, yaw)} rebuild the rotation with error {err:.3g}"


@settings(deadline=None)
@given(transforms())
def test_compose_with_inverse_is_identity(tau):
    for M in (tau.matrix() @ tau.inverse().matrix(), tau.inverse().matrix() @ tau.matrix(),
              compose(tau.matrix(), invert_pose(tau.matrix()))):
        err = np.abs(M - np.eye(4)).max()
        assert err < 1e-12, f"{tau}: tau composed with its inverse is off identity by {err:.3g}"


@settings(deadline=None)
@given(transforms(), transforms())
def test_then_equals_matrix_product(a, b):
    np.testing.assert_allclose(a.then(b).matrix(), a.matrix() @ b.matrix(), atol=1e-11)


@settings(deadline=None)
@given(poses(), transforms())
def test_apply_acts_in_the_source_camera_frame(c2w, tau):
    out = tau.apply(c2w, length=2.0)
    np.testing.assert_allclose(out[:3, 3], c2w[:3, 3] + c2w[:3, :3] @ (2.0 * tau.translation), atol=1e-12)
    np.testing.assert_allclose(out[:3, :3], c2w[:3, :3] @ tau.rotation, atol=1e-12)


@settings(max_examples=3, deadline=None)
@given(st.lists(transforms(), min_size=1, max_size=5))
def test_rotation_stays_orthonormal_after_10000_compositions(steps):
    M = np.eye(4)
    for k in range(10_000):
        M = compose(M, steps[k % len(steps)].matrix())
    R = M[:3, :3]
    err = np.linalg.norm(R.T @ R - np.eye(3))
    assert err < 1e-12, f"|R^T R - I| = {err:.3g} after 10 000 compositions"
    assert np.linalg.det(R) > 0


def test_rotation_order_is_yaw_then_pitch_then_roll():
    a, b, c = math.radians(10), math.radians(20), math.radians(30)
    Ry = np.array([[math.cos(c), 0, math.sin(c)], [0, 1, 0], [-math.sin(c), 0, math.cos(c)]])
    Rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    Rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    np.testing.assert_allclose(rotation_from_euler(10, 20, 30), Ry @ Rx @ Rz, atol=1e-15)


@pytest.mark.parametrize("p", [90.0, -90.0])
@settings(deadline=None)
@given(roll=roll_yaw, yaw=roll_yaw)
def test_gimbal_lock_gives_finite_angles_that_rebuild_the_rotation(p, roll, yaw):
    R = rotation_from_euler(roll, p, yaw)
    angles = euler_from_rotation(R)
    assert all(math.isfinite(a) for a in angles), angles
    assert angles[0] == 0.0, f"at gimbal lock all the turn goes into yaw, got roll={angles[0]}"
    assert angles[1] == pytest.approx(p, abs=1e-6)
    assert np.abs(rotation_from_euler(*angles) - R).max() < 1e-12
    tau = Transform(roll=roll, pitch=p, yaw=yaw)
    assert np.all(np.isfinite(tau.inverse().matrix()))


@settings(deadline=None)
@given(pitch)
def test_pitch_alone_round_trips_exactly_enough(p):
    assert Transform.from_matrix(Transform(pitch=p).matrix()).pitch == pytest.approx(p, abs=1e-9)


@pytest.mark.parametrize("name", ["roll", "pitch", "yaw", "x", "y", "z"])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_transform_raises_value_error_naming_the_argument(name, bad):
    with pytest.raises(ValueError, match=rf"\b{name}=") as exc:
        Transform(**{name: bad})
    assert "finite" in str(exc.value)


@pytest.mark.parametrize("name", ["roll", "pitch", "yaw"])
def test_out_of_range_angle_raises_value_error_naming_it(name):
    with pytest.raises(ValueError, match=rf"{name}=400.0 is out of range"):
        Transform(**{name: 400})


def test_wrong_types_raise_type_error():
    with pytest.raises(TypeError, match="yaw="):
        Transform(yaw="10")
    with pytest.raises(TypeError, match="roll="):
        rotation_from_euler(True, 0, 0)


@pytest.mark.parametrize("name", ["roll", "pitch", "yaw"])
def test_rotation_from_euler_rejects_nan(name):
    kwargs = {"roll": 0.0, "pitch": 0.0, "yaw": 0.0, name: math.nan}
    with pytest.raises(ValueError, match=name):
        rotation_from_euler(**kwargs)


def test_check_pose_names_the_problem():
    with pytest.raises(ValueError, match="c2w contains 1 non-finite"):
        M = np.eye(4)
        M[0, 3] = np.nan
        check_pose(M)
    with pytest.raises(ValueError, match="not a rotation"):
        check_pose(np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="last row"):
        M = np.eye(4)
        M[3, 0] = 1
        check_pose(M)
    with pytest.raises(TypeError, match=r"shape \(4 4\)"):
        check_pose(np.eye(3))


@settings(deadline=None)
@given(poses(), st.integers(0, 15), st.sampled_from([0.0, 1e-9, 2e-9, 1e-6, 1.1e-5, 1e-3, -1e-9, -2e-9, -1e-6]))
def test_check_pose_accepts_what_its_allclose_definition_accepts(c2w, entry, delta):
    """``check_pose``'s written-out tests are ``np.allclose`` on the last row (atol 1e-9) and ``np.linalg.det``."""
    M = np.array(c2w, dtype=np.float64)
    M.flat[entry] += delta
    R = M[:3, :3]
    expected = bool(np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9)
                    and np.abs(R.T @ R - np.eye(3)).max() <= 1e-5 and np.linalg.det(R) >= 0)
    try:
        check_pose(M)
        accepted = True
    except InvalidArgument:
        accepted = False
    assert accepted == expected, f"entry {entry} moved by {delta}: accepted {accepted}, np.allclose says {expected}"


def test_from_matrix_rejects_bad_length():
    with pytest.raises(ValueError, match="length"):
        Transform.from_matrix(np.eye(4), length=0.0)
    with pytest.raises(ValueError, match="length"):
        Transform(x=1).matrix(length=math.nan)


@pytest.mark.parametrize("p", [90 - 3.2e-8, -90 + 3.2e-8, 90 - 1e-12, 90 - 1e-5])
@settings(deadline=None)
@given(roll=roll_yaw, yaw=roll_yaw)
def test_near_gimbal_lock_euler_rebuilds_rotation_to_round_off(p, roll, yaw):
    """Regression: a gimbal-lock threshold of cos(pitch) <= 1e-9 rebuilt R with errors up to 2e-9."""
    R = rotation_from_euler(roll, p, yaw)
    err = np.abs(rotation_from_euler(*euler_from_rotation(R)) - R).max()
    assert err < 1e-12, f"pitch={p}: rebuild error {err:.3g}"


@settings(deadline=None)
@given(transforms())
def test_parse_reads_back_what_repr_lists(tau):
    text = ",".join(f"{k}={v!r}" for k, v in tau.as_dict().items() if v != 0.0)
    back = Transform.parse(text)
    assert back == tau, f"Transform.parse({text!r}) gave {back!r}, expected {tau!r}"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("yaw", r"'yaw' is not 'name=value'"),
        ("yaw=10,,x=1", r"'' is not 'name=value'"),
        ("spin=3", r"unknown component 'spin'; expected one of \['roll', 'pitch', 'yaw', 'x', 'y', 'z'\]"),
        ("yaw=1,yaw=2", r"'yaw' is given twice"),
        ("x=ten", r"x='ten' is not a number"),
        ("yaw=400", r"yaw=400.0 is out of range"),
        ("x=nan", r"x=nan must be finite"),
    ],
)
def test_parse_errors_name_the_option_and_the_bad_part(text, message):
    with pytest.raises(InvalidArgument, match=r"--transform=.*" + message):
        Transform.parse(text, name="--transform")


def test_parse_rejects_a_non_string():
    with pytest.raises(InvalidType, match=r"transform=10 must be a string"):
        Transform.parse(10)


@pytest.mark.parametrize(("tau", "expected"), [
    (Transform(yaw=0.898), "yaw=+0.898°"),  # as the docs and the tutorial show it
    (Transform(yaw=-12.5, x=0.1), "yaw=-12.500°, x=+0.1 ref"),
    (Transform(yaw=0.0001), "yaw=+0.0001°"),
    (Transform(pitch=-0.0049), "pitch=-0.0049°"),
    (Transform(roll=2.3e-05), "roll=+2.3e-05°"),
    (Transform(yaw=3.0, roll=1e-15), "yaw=+3.000°"),
    (Transform(pitch=-1e-13), "identity"),
])
def test_describe_shows_small_angles_and_leaves_out_float_noise(tau, expected):
    assert tau.describe() == expected, (f"{tau!r}.describe() is {tau.describe()!r}, expected {expected!r}: a small "
                                        "non-zero angle must not read +0.000° and float noise is left out")


def test_a_translation_beyond_float64_is_refused_naming_the_transform():
    """Transform(x=1e308) applied with a length of 10 gave a pose of inf and NaN, with only a RuntimeWarning."""
    with pytest.raises(InvalidArgument, match=r"Transform\(x=1e\+308\) with length=10.0 moves the camera beyond "
                                              r"float64"):
        Transform(x=1e308).apply(np.eye(4), 10.0)
