"""A lens model that folds over within the image is refused where pixels are undistorted (Camera.check_lens)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pytest_n2r.data.colmap import camera_from_colmap
from pytest_n2r.data.ingest import _undistorted_image
from pytest_n2r.data.poses import SourceFrame
from pytest_n2r.errors import IngestError, InvalidArgument
from pytest_n2r.geometry import Camera

WIDE = camera_from_colmap("SIMPLE_RADIAL", 400, 300, [180.0, 200.0, 150.0, -0.25])  # r_d' = 0 at r 1.155 < 1.389


def _column_ramp(camera: Camera) -> np.ndarray:
    """Each pixel's red = its own column scaled to 0..255, so a remapped pixel says which column it came from."""
    u = np.tile(np.arange(camera.width), (camera.height, 1))
    return np.repeat((u * 255 // (camera.width - 1))[..., None], 3, -1).astype(np.uint8)


@pytest.mark.parametrize(("camera", "expected"), [
    (WIDE, ("Camera distortion (k1, k2, p1, p2)=(-0.25, 0.0, 0.0, 0.0) folds over at normalized radius 1.155 (the "
            "distorted radius stops increasing there), inside the radius 1.389 of the image's corners")),
    (Camera(400, 300, 180.0, 180.0, 199.5, 149.5, (-1.0, -5.0, 0.0, 0.0, 0.0, 0.0, 0.0, -30.0)),
     ("(k1, k2, p1, p2, k3, k4, k5, k6)=(-1.0, -5.0, 0.0, 0.0, 0.0, 0.0, 0.0, -30.0) folds over at normalized "
      "radius 0.5676 (its rational denominator reaches 0 there), inside the radius 1.389")),
    (Camera(64, 48, 40.0, 40.0, 31.5, 23.5, (1e300, 0.0, 0.0, 0.0)),
     ("(k1, k2, p1, p2)=(1e+300, 0.0, 0.0, 0.0) moves the image's corner (normalized radius 1) 4e+301 pixels from "
      "the principal point, beyond a float32 remap table")),
])
def test_undistorting_through_a_lens_that_folds_over_is_refused(camera, expected):
    image = _column_ramp(camera)
    try:
        out = camera.undistort_image(image)
    except InvalidArgument as exc:
        assert expected in str(exc), f"the refusal does not name the lens, the fold and the corner: {exc}"
    else:
        pytest.fail(f"{camera.distortion} folds over (or overflows) inside the image's corners, yet undistort_image "
                    f"returned a picture (top-left source columns {out[0, :80:20, 0].tolist()}, mean "
                    f"{out.mean():.1f}) that a fit would train on")


def test_the_wide_lens_does_mirror_its_corners_so_the_refusal_is_not_overcautious():
    """OpenCV's own map for the refused lens: along the top row the source column first falls, then rises again."""
    map_u, _ = cv2.initUndistortRectifyMap(WIDE.K, np.asarray(WIDE.distortion), None, WIDE.K, WIDE.size,
                                           cv2.CV_32FC1)
    row = map_u[0, :100]
    assert (np.diff(row) < 0).any(), f"the map of the top row never turns back: {row[::20].tolist()}"


def test_a_lens_that_folds_only_beyond_the_corners_is_used():
    """k1 = -0.25 folds at r 1.155: a narrower view of the same lens (corner radius 1.067) undistorts."""
    camera = Camera(200, 160, 120.0, 120.0, 99.5, 79.5, (-0.25, 0.0, 0.0, 0.0))
    assert camera.corner_radius() < 1.155 and camera.check_lens() is camera
    assert camera.undistort_image(_column_ramp(camera)).shape == (160, 200, 3)


def test_a_folding_lens_is_still_a_camera_to_keep_and_write():
    """The check is where pixels are undistorted: a scene file or a pose set may carry the numbers."""
    assert Camera.from_dict(WIDE.to_dict()) == WIDE


def test_ingestion_names_the_photo_whose_lens_folds_over(tmp_path):
    path = tmp_path / "wide.png"
    cv2.imwrite(str(path), _column_ramp(WIDE))
    frame = SourceFrame("wide.png", path, WIDE, np.eye(4))
    try:
        _undistorted_image(frame, as_stored=True)
    except IngestError as exc:
        message = str(exc)
    except InvalidArgument as exc:
        pytest.fail(f"ingestion let the camera's error out without naming the photo: {exc}")
    else:
        pytest.fail("ingestion undistorted a photo through a lens that folds over (mirrored corners)")
    assert str(path) in message and "'wide.png'" in message and "folds over at normalized radius 1.155" in message, (
        f"the ingest error does not name the photo, its camera and the fold: {message}")
