"""Projecting into many cameras at once, and the half-open image bounds every "seen" test shares."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r import InvalidArgument
from pytest_n2r.geometry import Camera, CameraStack, inside_image, pixels_from_camera, project

from .strategies import cameras, poses


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_points=st.integers(0, 300), cams=st.lists(st.tuples(cameras(), poses()),
                                                                                       min_size=1, max_size=20))
def test_stack_sees_what_projecting_into_each_camera_sees(seed, n_points, cams):
    """One array operation for all cameras agrees point for point with :func:`project` into each camera apart
    (behind the camera, outside the image, on either side)."""
    points = np.random.default_rng(seed).normal(scale=3.0, size=(n_points, 3))
    stack = CameraStack.of([c for c, _ in cams], [p for _, p in cams])
    u, v, z = stack.project(points)
    sees = stack.sees(points)
    assert sees.shape == u.shape == (len(cams), n_points)
    for k, (camera, c2w) in enumerate(cams):
        uv_one, z_one = project(points, camera, c2w)
        np.testing.assert_allclose(z[k], z_one, rtol=1e-12, atol=1e-9, err_msg=f"camera {k}: z-depths differ")
        np.testing.assert_allclose(np.stack([u[k], v[k]], -1), uv_one, rtol=1e-9, atol=1e-6,
                                   err_msg=f"camera {k}: pixel coordinates differ")
        expected = (z_one > 0) & inside_image(uv_one[:, 0], uv_one[:, 1], camera.width, camera.height)
        assert np.array_equal(sees[k], expected), f"camera {k}: {int((sees[k] != expected).sum())} points disagree"


def test_inside_image_is_half_open_on_pixel_borders():
    """Pixel centres are at integers: the image of a 4x3 camera spans [-0.5, 3.5) x [-0.5, 2.5)."""
    u = np.array([-0.5, 3.49, 3.5, -0.51, 0.0, 0.0, np.nan])
    v = np.array([-0.5, 2.49, 0.0, 0.0, 2.5, -0.51, 0.0])
    assert inside_image(u, v, 4, 3).tolist() == [True, True, False, False, False, False, False]


def test_pixels_from_camera_is_nan_behind_and_on_the_camera_plane():
    u, v = pixels_from_camera(np.ones(3), np.ones(3), np.array([1.0, 0.0, -1.0]), 10.0, 20.0, 5.0, 6.0)
    assert (u[0], v[0]) == (15.0, 26.0)
    assert np.isnan(u[1:]).all() and np.isnan(v[1:]).all(), (u, v)


def test_an_empty_stack_sees_nothing_and_a_pose_count_mismatch_is_named():
    assert CameraStack.of([], []).sees(np.zeros((4, 3))).shape == (0, 4)
    with pytest.raises(InvalidArgument, match=r"CameraStack.of: 2 cameras but 1 poses"):
        CameraStack.of([Camera(4, 3, 1.0, 1.0, 1.5, 1.0)] * 2, [np.eye(4)])
