"""Plane-induced and rotation homographies agree with back-projection and projection."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pytest_n2r.geometry import (
    Camera,
    Transform,
    apply_homography,
    backproject,
    camera_rays,
    plane_homography,
    project,
    rotation_homography,
)

from .strategies import cameras

#: Plane normals that camera a (looking along +z) sees: |n_z| >= 0.3, drawn directly instead of filtered
#: (filtering three quarters of the draws tripped Hypothesis's filter_too_much health check).
facing_normals = st.builds(
    lambda nz, phi, sign: np.array([np.sqrt(1 - nz**2) * np.cos(phi), np.sqrt(1 - nz**2) * np.sin(phi), sign * nz]),
    st.floats(0.3, 1.0), st.floats(0.0, 2 * np.pi), st.sampled_from([-1.0, 1.0]),
)
small_tau = st.builds(
    Transform, roll=st.floats(-20, 20), pitch=st.floats(-20, 20), yaw=st.floats(-20, 20),
    x=st.floats(-0.5, 0.5), y=st.floats(-0.5, 0.5), z=st.floats(-0.5, 0.5),
)


@settings(deadline=None)
@given(cameras(), cameras(), small_tau, facing_normals, st.floats(2.0, 10.0))
def test_plane_homography_equals_project_of_backproject_on_the_plane(cam_a, cam_b, tau, normal, dist):
    c2w_a = np.eye(4)
    c2w_b = tau.apply(c2w_a)
    n = normal / np.linalg.norm(normal)
    d = -dist * abs(n[2])  # plane n.X + d = 0 crosses the optical axis ahead of camera a
    uv = np.array([[cam_a.cx, cam_a.cy], [0.0, 0.0], [cam_a.width - 1.0, cam_a.height - 1.0]])
    origins, dirs = camera_rays(cam_a, c2w_a, uv)
    t = -(origins @ n + d) / (dirs @ n)
    assume(np.all(t > 0.1))
    X = backproject(uv, t, cam_a, c2w_a)
    expected, z_b = project(X, cam_b, c2w_b)
    assume(np.all(z_b > 0.1))
    H = plane_homography(cam_a, c2w_a, cam_b, c2w_b, n, d)
    np.testing.assert_allclose(apply_homography(H, uv), expected, atol=1e-6 * (1 + np.abs(expected).max()))


@settings(deadline=None)
@given(cameras(), small_tau, st.floats(0.5, 100.0))
def test_rotation_homography_maps_points_at_any_depth(cam, tau, depth):
    rot_only = Transform(roll=tau.roll, pitch=tau.pitch, yaw=tau.yaw)
    c2w_b = rot_only.apply(np.eye(4))
    uv = np.array([[cam.cx, cam.cy], [1.0, 2.0], [cam.width - 3.0, cam.height / 2]])
    X = backproject(uv, np.full(3, depth), cam, np.eye(4))
    expected, z = project(X, cam, c2w_b)
    assume(np.all(z > 1e-3 * depth))
    H = rotation_homography(cam, np.eye(4), cam, c2w_b)
    np.testing.assert_allclose(apply_homography(H, uv), expected, atol=1e-6 * (1 + np.abs(expected).max()))


def test_plane_through_camera_centre_raises():
    cam = Camera(64, 48, 50.0, 50.0, 31.5, 23.5)
    with pytest.raises(ValueError, match="passes through camera a's centre"):
        plane_homography(cam, np.eye(4), cam, np.eye(4), np.array([0.0, 0.0, 1.0]), 0.0)
