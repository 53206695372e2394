"""OpenGL <-> OpenCV and COLMAP quaternion conversions, checked against their definitions and pycolmap."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings

from pytest_n2r.geometry import c2w_from_colmap, colmap_from_c2w, opencv_to_opengl, opengl_to_opencv
from pytest_n2r.geometry.conventions import quaternion_to_rotation, rotation_to_quaternion

from .strategies import poses

pycolmap = pytest.importorskip("pycolmap")


@settings(deadline=None)
@given(poses())
def test_opengl_opencv_round_trip(c2w):
    np.testing.assert_allclose(opengl_to_opencv(opencv_to_opengl(c2w)), c2w, atol=1e-12)


@settings(deadline=None)
@given(poses())
def test_opengl_camera_looks_down_its_minus_z(c2w):
    gl = opencv_to_opengl(c2w)
    np.testing.assert_allclose(gl[:3, 2], -c2w[:3, 2], atol=1e-15)  # backward axis = -forward
    np.testing.assert_allclose(gl[:3, 1], -c2w[:3, 1], atol=1e-15)  # up = -down
    np.testing.assert_allclose(gl[:3, 0], c2w[:3, 0], atol=1e-15)
    np.testing.assert_allclose(gl[:3, 3], c2w[:3, 3], atol=1e-15)


@settings(deadline=None)
@given(poses())
def test_colmap_round_trip_and_canonical_quaternion(c2w):
    q, t = colmap_from_c2w(c2w)
    assert q[0] >= 0 and np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(c2w_from_colmap(q, t), c2w, atol=1e-12)


@settings(deadline=None)
@given(poses())
def test_quaternions_agree_with_pycolmap(c2w):
    """pycolmap (Eigen, xyzw order) is an independent implementation of COLMAP's convention."""
    q, t = colmap_from_c2w(c2w)
    w2c = pycolmap.Rigid3d(pycolmap.Rotation3d(np.array([q[1], q[2], q[3], q[0]])), t).matrix()
    np.testing.assert_allclose(w2c, np.linalg.inv(c2w)[:3], atol=1e-12)
    x, y, z, w = pycolmap.Rotation3d(np.linalg.inv(c2w)[:3, :3]).quat
    theirs = np.array([w, x, y, z]) * (1 if w >= 0 else -1)
    np.testing.assert_allclose(rotation_to_quaternion(np.linalg.inv(c2w)[:3, :3]), theirs, atol=1e-12)


def test_zero_quaternion_raises():
    with pytest.raises(ValueError, match="qvec has zero length"):
        quaternion_to_rotation(np.zeros(4))


def test_non_finite_transform_matrix_raises_naming_it():
    M = np.eye(4)
    M[1, 1] = np.nan
    with pytest.raises(ValueError, match="transform_matrix contains 1 non-finite"):
        opengl_to_opencv(M)
