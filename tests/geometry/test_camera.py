"""Camera intrinsics: the resize rule, COLMAP pixel convention, undistortion, bad values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.geometry import Camera, backproject, project

from .strategies import cameras


@settings(deadline=None)
@given(cameras(), st.integers(8, 3000), st.integers(8, 3000), st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_resized_keeps_image_borders_where_they_were(cam, w, h, fu, fv):
    """A point seen at a fraction of the image width/height stays at that fraction after resizing."""
    small = cam.resized(w, h)
    u, v = -0.5 + fu * cam.width, -0.5 + fv * cam.height  # pixel-edge coordinates
    X = backproject(np.array([[u, v]]), np.array([2.0]), cam, np.eye(4))
    uv, _ = project(X, small, np.eye(4))
    np.testing.assert_allclose(uv[0], [-0.5 + fu * w, -0.5 + fv * h], atol=1e-7 * max(w, h, cam.width, cam.height))


@settings(deadline=None)
@given(cameras(), st.integers(8, 3000), st.integers(8, 3000))
def test_resized_there_and_back_is_identity(cam, w, h):
    back = cam.resized(w, h).resized(cam.width, cam.height)
    for name in ("fx", "fy", "cx", "cy"):
        assert getattr(back, name) == pytest.approx(getattr(cam, name), rel=1e-12, abs=1e-9)


def test_resize_rule_by_hand():
    cam = Camera(1080, 1920, 1375.52, 1374.49, 554.058, 964.768).scaled(0.25)
    assert (cam.width, cam.height) == (270, 480)
    assert cam.fx == pytest.approx(343.88)
    assert cam.cx == pytest.approx((554.058 + 0.5) * 0.25 - 0.5)


@pytest.mark.parametrize(("width", "height", "error", "message"), [
    (320.5, 240, InvalidType, "Camera.resized width=320.5 must be an int (pixels)"),
    (320, 240.0, InvalidType, "Camera.resized height=240.0 must be an int (pixels)"),
    (True, 240, InvalidType, "Camera.resized width=True must be an int (pixels)"),
    (320, 0, InvalidArgument, "Camera.resized height=0 must be >= 1 pixel"),
    (-4, 240, InvalidArgument, "Camera.resized width=-4 must be >= 1 pixel"),
])
def test_resized_to_a_size_that_is_not_whole_pixels_is_refused_naming_it(width, height, error, message):
    """A fractional size would scale the intrinsics by one size and store another: refused, not rounded."""
    cam = Camera(640, 480, 500.0, 500.0, 319.5, 239.5)
    with pytest.raises(error) as info:
        cam.resized(width, height)
    assert str(info.value) == message, f"resized({width!r}, {height!r}) raised {info.value!r}; expected {message!r}"


def test_resized_takes_numpy_ints():
    small = Camera(640, 480, 500.0, 500.0, 319.5, 239.5).resized(np.int64(320), np.int32(240))
    assert (small.width, small.height, small.fx) == (320, 240, 250.0), f"resized to numpy ints gave {small}"
    assert type(small.width) is int, f"the width is stored as {type(small.width).__name__}, not int"


def test_colmap_pixels_shift_by_half():
    cam = Camera.from_colmap_pixels(640, 480, 500.0, 500.0, 320.0, 240.0)
    assert (cam.cx, cam.cy) == (319.5, 239.5)


def test_undistort_image_straightens_a_distorted_line():
    """A straight edge imaged through barrel distortion bends; undistortion makes it straight again."""
    import cv2

    ideal = Camera(200, 160, 120.0, 120.0, 99.5, 79.5)
    cam = Camera(200, 160, 120.0, 120.0, 99.5, 79.5, (-0.25, 0.05, 0.0, 0.0))
    # Render the distorted image of a vertical edge at u = 150 in the ideal image.
    grid = np.stack(np.meshgrid(np.arange(200.0), np.arange(160.0)), -1).reshape(-1, 1, 2)
    undist = cv2.undistortPoints(grid, cam.K, np.array(cam.distortion), P=cam.K).reshape(160, 200, 2)
    distorted = np.where(undist[..., 0] < 150, 255, 0).astype(np.uint8)
    distorted = np.repeat(distorted[..., None], 3, axis=2)
    fixed = cam.undistort_image(distorted)
    edge_cols = [int(np.argmax(fixed[r, :, 0] < 128)) for r in range(10, 150, 10)]
    assert max(edge_cols) - min(edge_cols) <= 1, f"edge columns after undistortion: {edge_cols}"
    raw_cols = [int(np.argmax(distorted[r, :, 0] < 128)) for r in range(10, 150, 10)]
    assert max(raw_cols) - min(raw_cols) >= 3, "test image is not distorted enough to prove anything"
    assert ideal.K.tolist() == cam.undistorted().K.tolist() and cam.undistorted().distortion == ()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fx": -1.0}, "fx=-1.0 must be > 0"),
        ({"fy": math.nan}, "fy=nan must be finite"),
        ({"cx": math.inf}, "cx=inf must be finite"),
        ({"width": 0}, "width=0 must be >= 1"),
        ({"distortion": (0.1, 0.2)}, "2 coefficients"),
    ],
)
def test_bad_camera_values_raise_value_error(kwargs, match):
    args = {"width": 64, "height": 48, "fx": 50.0, "fy": 50.0, "cx": 31.5, "cy": 23.5, **kwargs}
    with pytest.raises(ValueError, match=match):
        Camera(**args)


def test_camera_dict_round_trip_and_missing_field():
    cam = Camera(64, 48, 50.0, 51.0, 31.5, 23.5, (0.1, 0.0, 0.0, 0.0))
    assert Camera.from_dict(cam.to_dict()) == cam
    with pytest.raises(ValueError, match="'fx'"):
        Camera.from_dict({"width": 64, "height": 48})


def test_distortion_is_stored_without_trailing_zero_terms():
    def dist(coeffs):
        return Camera(64, 48, 50.0, 50.0, 31.5, 23.5, coeffs).distortion

    assert dist((0.1, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0)) == (0.1, 0.0, 0.0, 0.0, 0.2)
    assert dist((0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)) == (0.1, 0.0, 0.0, 0.0)
    assert dist((0.1, 0.0, 0.0, 0.0, 0.0)) == (0.1, 0.0, 0.0, 0.0)
    assert dist((0.0, 0.0, 0.0, 0.0, 0.0)) == ()
    assert dist((0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3)) == (0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.3)


@pytest.mark.parametrize(("K", "match"), [
    (2 * Camera(640, 480, 500, 500, 319.5, 239.5).K, r"K's last row is \[0.0, 0.0, 2.0\]; expected \[0, 0, 1\]"),
    ([[500, 30, 319.5], [0, 500, 239.5], [0, 0, 1]], r"K has skew or shear \(K\[0, 1\]=30.0"),
    ([[500, 0, 319.5], [0, 500, 239.5], [0.1, 0, 1]], r"K's last row is \[0.1, 0.0, 1.0\]"),
    ([[500, 0, 319.5], [4, 500, 239.5], [0, 0, 1]], r"K\[1, 0\]=4.0"),
    ([[500, 0, 319.5], [0, 500, np.nan], [0, 0, 1]], r"K contains 1 non-finite"),
])
def test_from_k_refuses_a_matrix_this_camera_model_cannot_hold(K, match):
    """A scaled K was read as another camera (fx 1000, cx 639) and a skew was dropped, silently."""
    with pytest.raises(InvalidArgument, match=match):
        Camera.from_K(K, 640, 480)
    assert Camera.from_K(Camera(640, 480, 500, 510, 319.5, 239.5).K, 640, 480) == Camera(640, 480, 500, 510, 319.5,
                                                                                           239.5)
    rounded = Camera(640, 480, 500, 510, 319.5, 239.5).K + [[0, 1e-12, 0], [1e-13, 0, 0], [0, 0, 2e-16]]
    assert Camera.from_K(rounded, 640, 480).fx == 500, "a K decomposed from a projection matrix has rounding"
