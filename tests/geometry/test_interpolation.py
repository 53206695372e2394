"""Pose interpolation: slerp turns at constant speed about one axis, centres move on a straight line."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.geometry import rotation_angle_deg, rotation_from_euler
from pytest_n2r.geometry.interpolation import interpolate_c2w, rotation_vector, slerp_rotation

from .strategies import poses

fractions = st.floats(0.0, 1.0)


@given(start=poses(), end=poses(), t=fractions)
def test_slerp_turns_a_fraction_t_of_the_angle_and_the_rest_remains(start, end, t):
    R0, R1 = start[:3, :3], end[:3, :3]
    total = rotation_angle_deg(R0, R1)
    Rt = slerp_rotation(R0, R1, t)
    # a half turn has two shorter ways round, each turning t of it: the angles hold up to 180 degrees
    assert rotation_angle_deg(R0, Rt) == pytest.approx(t * total, abs=1e-6)
    assert rotation_angle_deg(Rt, R1) == pytest.approx((1 - t) * total, abs=1e-6)
    np.testing.assert_allclose(Rt.T @ Rt, np.eye(3), atol=1e-9)


@given(start=poses(), end=poses(), t=fractions)
def test_interpolated_centres_lie_on_the_segment(start, end, t):
    c2w = interpolate_c2w(start, end, t)
    np.testing.assert_allclose(c2w[:3, 3], start[:3, 3] + t * (end[:3, 3] - start[:3, 3]), atol=1e-9)
    np.testing.assert_array_equal(c2w[3], [0.0, 0.0, 0.0, 1.0])


@given(start=poses())
def test_the_rotation_vector_turns_back_into_the_rotation_whatever_its_angle(start):
    """Drawn rotations, and the same turned by nearly and exactly half a turn about a drawn axis of theirs."""
    for R in (start[:3, :3], start[:3, :3] @ cv2.Rodrigues(np.pi * start[:3, 0])[0],
              start[:3, :3] @ cv2.Rodrigues((np.pi - 1e-9) * start[:3, 1])[0]):
        vector = rotation_vector(R)
        assert np.linalg.norm(vector) <= np.pi + 1e-12, f"angle {np.linalg.norm(vector)} over a half turn"
        np.testing.assert_allclose(cv2.Rodrigues(vector)[0], R, atol=1e-12,
                                   err_msg=f"the rotation vector {vector} is not the rotation's")


@pytest.mark.parametrize("degrees", [179.999, 179.9994, 179.99999, 180.0])
def test_the_end_of_a_turn_of_nearly_half_a_turn_is_the_given_pose(degrees):
    """Hypothesis found the end of a 179.9994° turn 2e-5 off through Rodrigues' logarithm (an axis read from a
    vanishing skew part); the quaternion keeps it."""
    start = np.eye(4)
    start[:3, :3] = rotation_from_euler(0.0, 35.0, 0.0)
    axis = np.array([0.3, -0.8, 0.52]) / np.linalg.norm([0.3, -0.8, 0.52])
    half, _ = cv2.Rodrigues(np.radians(degrees) * axis)
    end = start.copy()
    end[:3, :3] = start[:3, :3] @ half
    np.testing.assert_allclose(interpolate_c2w(start, end, 1.0), end, atol=1e-12,
                               err_msg=f"a {degrees}° turn does not end at the given pose")
    assert rotation_angle_deg(start[:3, :3], interpolate_c2w(start, end, 0.5)[:3, :3]) == \
        pytest.approx(degrees / 2, abs=1e-6), f"half of a {degrees}° turn"


@given(start=poses(), end=poses())
def test_the_ends_are_the_given_poses(start, end):
    """Up to a half turn: Rodrigues' logarithm, used before, ended 2e-5 off at 179.9994° (a Hypothesis example)."""
    np.testing.assert_array_equal(interpolate_c2w(start, end, 0.0), start)
    np.testing.assert_allclose(interpolate_c2w(start, end, 1.0), end, atol=1e-12)


def test_the_end_near_a_half_turn_is_as_accurate_as_the_warning_says():
    start, end = np.eye(4), np.eye(4)
    for degrees, tolerance in ((179.99, 1e-11), (179.999, 1e-11), (179.9999, 1e-5)):
        end[:3, :3] = rotation_from_euler(0, 0, degrees)
        assert np.abs(interpolate_c2w(start, end, 1.0) - end).max() < tolerance, degrees


@pytest.mark.parametrize("degrees", [1e-5, 1e-3, 5e-4])
def test_a_turn_too_small_for_opencvs_logarithm_is_kept(degrees):
    """OpenCV's Rodrigues reads a rotation with a sine below 1e-5 as none; slerp must still reach the end
    and go half way at t = 0.5 (a Hypothesis example at 1e-5 degrees found the end off by 1.7e-7). Just above
    that threshold OpenCV's own logarithm is good to 7e-12 (measured at 1e-3 degrees), hence the tolerance."""
    end = np.eye(4)
    end[:3, :3] = rotation_from_euler(0, degrees, 0)
    np.testing.assert_allclose(interpolate_c2w(np.eye(4), end, 1.0), end, rtol=0, atol=1e-11)
    half = slerp_rotation(np.eye(3), end[:3, :3], 0.5)
    np.testing.assert_allclose(half, rotation_from_euler(0, degrees / 2, 0), rtol=0, atol=1e-11)


def test_bad_arguments_are_named():
    with pytest.raises(InvalidArgument, match=r"t=-0.5 is out of range; expected a value in \[0, 1\]"):
        interpolate_c2w(np.eye(4), np.eye(4), -0.5)
    with pytest.raises(InvalidType, match=r"c2w_end must have shape \(4 4\), got \(3, 3\)"):
        interpolate_c2w(np.eye(4), np.eye(3), 0.5)
    with pytest.raises(InvalidType, match=r"R_start must have shape \(3 3\)"):
        slerp_rotation(np.eye(4), np.eye(3), 0.5)
