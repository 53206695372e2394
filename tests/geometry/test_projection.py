"""Projection with z-depth, back-projection, rays, and the sign conventions seen on projected points."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from pytest_n2r.geometry import Camera, Transform, backproject, camera_rays, project

from .strategies import cameras, poses

CAM = Camera(640, 480, 500.0, 500.0, 319.5, 239.5)


@st.composite
def pixels_and_depths(draw, camera: Camera, n: int = 8):
    uv = np.array([[draw(st.floats(-0.5, camera.width - 0.5)), draw(st.floats(-0.5, camera.height - 0.5))]
                   for _ in range(n)])
    depth = np.array([draw(st.floats(0.01, 100.0)) for _ in range(n)])
    return uv, depth


@settings(deadline=None)
@given(st.data(), cameras(), poses())
def test_project_after_backproject_is_identity(data, camera, c2w):
    uv, depth = data.draw(pixels_and_depths(camera))
    uv2, z = project(backproject(uv, depth, camera, c2w), camera, c2w)
    np.testing.assert_allclose(z, depth, rtol=1e-10)
    np.testing.assert_allclose(uv2, uv, atol=1e-7)


@settings(deadline=None)
@given(cameras(), poses(), st.lists(st.tuples(*[st.floats(-5, 5)] * 2, st.floats(0.1, 50)), min_size=1, max_size=8))
def test_backproject_after_project_is_identity(camera, c2w, pts_cam):
    X = np.array(pts_cam) @ c2w[:3, :3].T + c2w[:3, 3]  # points in front of the camera, world frame
    uv, z = project(X, camera, c2w)
    np.testing.assert_allclose(backproject(uv, z, camera, c2w), X, atol=1e-8 * (1 + np.abs(X).max()))


@settings(deadline=None)
@given(cameras(), poses())
def test_ray_parameter_is_z_depth(camera, c2w):
    uv = np.array([[0.0, 0.0], [camera.width - 1.0, camera.height - 1.0]])
    origins, dirs = camera_rays(camera, c2w, uv)
    d_cam = dirs @ c2w[:3, :3]  # back to the camera frame
    np.testing.assert_allclose(d_cam[:, 2], 1.0, atol=1e-12)
    _, z = project(origins + 3.0 * dirs, camera, c2w)
    np.testing.assert_allclose(z, 3.0, rtol=1e-12)


def test_principal_point_and_pixel_centres():
    uv, _ = project(np.array([[0.0, 0.0, 2.0], [-0.5 * 2 * 319.5 / 500 * 1.0, 0.0, 1.0]]), CAM, np.eye(4))
    np.testing.assert_allclose(uv[0], [319.5, 239.5])
    assert uv[1, 0] == pytest.approx(0.0)  # the left pixel's centre is u = 0


def test_points_behind_the_camera_have_nan_pixels_and_their_depth():
    uv, z = project(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0]]), CAM, np.eye(4))
    assert np.isnan(uv).all()
    np.testing.assert_array_equal(z, [-1.0, 0.0])


def test_bad_input_names_the_argument():
    with pytest.raises(ValueError, match="points_world contains 1 non-finite"):
        project(np.array([[0.0, np.nan, 1.0]]), CAM, np.eye(4))
    with pytest.raises(TypeError, match=r"points_world must have shape \(N 3\)"):
        project(np.zeros((2, 2)), CAM, np.eye(4))
    with pytest.raises(ValueError, match="depth contains"):
        backproject(np.zeros((1, 2)), np.array([np.inf]), CAM, np.eye(4))


# --- sign conventions, checked where they matter: on projected points ---------------------------------

ahead = st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(1.0, 10.0)).map(
    lambda p: np.array([[p[0] * p[2], p[1] * p[2], p[2]]])
)  # within ~27 degrees of the optical axis
angle = st.floats(0.5, 25.0)


def _moved(point: np.ndarray, tau: Transform) -> tuple[np.ndarray, np.ndarray]:
    before, _ = project(point, CAM, np.eye(4))
    after, _ = project(point, CAM, tau.apply(np.eye(4)))
    return before[0], after[0]


@settings(deadline=None)
@given(ahead, angle)
def test_positive_yaw_moves_points_left(point, a):
    before, after = _moved(point, Transform(yaw=a))
    assert after[0] < before[0], f"yaw=+{a}: u went {before[0]:.2f} -> {after[0]:.2f}, expected left"


@settings(deadline=None)
@given(ahead, angle)
def test_positive_pitch_moves_points_down(point, a):
    before, after = _moved(point, Transform(pitch=a))
    assert after[1] > before[1], f"pitch=+{a}: v went {before[1]:.2f} -> {after[1]:.2f}, expected down"


@settings(deadline=None)
@given(ahead, angle)
def test_positive_roll_turns_content_counter_clockwise(point, a):
    before, after = _moved(point, Transform(roll=a))
    c = np.array([CAM.cx, CAM.cy])
    rb, ra = before - c, after - c
    assume(np.linalg.norm(rb) > 1.0)
    # On screen (v down) counter-clockwise means the angle atan2(-dv, du) increases by exactly `a`.
    turn = math.degrees(math.atan2(-ra[1], ra[0]) - math.atan2(-rb[1], rb[0]))
    turn = (turn + 180) % 360 - 180
    assert turn == pytest.approx(a, abs=1e-6), f"roll=+{a}: content turned {turn:.4f} deg (ccw positive)"


@settings(deadline=None)
@given(ahead, st.floats(0.01, 0.5))
def test_positive_x_moves_camera_right_so_points_move_left(point, d):
    before, after = _moved(point, Transform(x=d))
    assert after[0] < before[0] and after[1] == pytest.approx(before[1], abs=1e-9 + abs(before[1] - CAM.cy))


@settings(deadline=None)
@given(ahead, st.floats(0.01, 0.5))
def test_positive_y_moves_camera_down_so_points_move_up(point, d):
    before, after = _moved(point, Transform(y=d))
    assert after[1] < before[1], f"y=+{d}: v went {before[1]:.2f} -> {after[1]:.2f}, expected up"


@settings(deadline=None)
@given(ahead, st.floats(0.01, 0.9))
def test_positive_z_moves_camera_forward_so_points_spread_out(point, d):
    assume(np.hypot(point[0, 0], point[0, 1]) > 1e-3)
    before, after = _moved(point, Transform(z=d))
    c = np.array([CAM.cx, CAM.cy])
    assert np.linalg.norm(after - c) > np.linalg.norm(before - c)
    # ... along the same direction from the principal point
    cross = (after - c)[0] * (before - c)[1] - (after - c)[1] * (before - c)[0]
    assert abs(cross) < 1e-6 * np.linalg.norm(after - c) * np.linalg.norm(before - c) + 1e-9
