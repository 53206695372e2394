"""The neighbouring-photo yardstick of ``benchmarks/fidelity.py --neighbours`` (``benchmarks/_neighbours.py``):
an image brought from one camera to another through depth lands where the geometry says, keeps the render where
the other camera does not see the point, and the optical-flow alignment undoes a shift."""

from __future__ import annotations

import sys
from types import SimpleNamespace

import numpy as np
import pytest

from pytest_n2r.geometry import Camera
from pytest_n2r.metrics.image_quality import psnr

from .conftest import REPO_ROOT


@pytest.fixture(scope="module")
def neighbours():
    sys.path.insert(0, str(REPO_ROOT / "benchmarks"))  # as when run: the helpers sit beside the scripts
    try:
        import _neighbours
    finally:
        sys.path.remove(str(REPO_ROOT / "benchmarks"))
    return _neighbours


CAMERA = Camera(64, 48, fx=50.0, fy=50.0, cx=31.5, cy=23.5)
DEPTH = np.full((48, 64), 2.0, dtype=np.float32)  # a wall 2 units in front, facing the camera
OPAQUE = np.ones((48, 64), dtype=np.float32)


def _texture(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (48, 64, 3), dtype=np.uint8)


def _at(x: float) -> np.ndarray:
    c2w = np.eye(4)
    c2w[0, 3] = x
    return c2w


def test_an_image_brought_to_its_own_pose_is_itself(neighbours):
    image = _texture()
    brought, share = neighbours.brought_to(CAMERA, _at(0.0), DEPTH, OPAQUE, np.zeros_like(image), image, _at(0.0),
                                           DEPTH, CAMERA)
    assert share == 1.0, f"every pixel sees itself, got a share of {share}"
    assert np.array_equal(brought, image), f"max difference {np.abs(brought.astype(int) - image).max()}"


def test_a_sideways_step_moves_the_wall_by_the_disparity(neighbours):
    # The other camera is 0.16 units right: a point on the wall lands fx * 0.16 / 2 = 4 px further left in it.
    image, render = _texture(), np.full((48, 64, 3), 7, dtype=np.uint8)
    brought, share = neighbours.brought_to(CAMERA, _at(0.0), DEPTH, OPAQUE, render, image, _at(0.16), DEPTH, CAMERA)
    assert np.array_equal(brought[:, 4:], image[:, :-4]), "the wall's texture did not land 4 px to the right"
    assert (brought[:, :4] == 7).all(), "pixels the other camera does not see must keep the render's colour"
    assert share == pytest.approx(60 / 64)


def test_a_point_the_other_camera_sees_something_nearer_at_keeps_the_render(neighbours):
    image, render = _texture(), np.full((48, 64, 3), 7, dtype=np.uint8)
    nearer = DEPTH.copy()
    nearer[:, :32] = 1.0  # an occluder in front of the left half of the wall, as the other camera sees it
    brought, share = neighbours.brought_to(CAMERA, _at(0.0), DEPTH, OPAQUE, render, image, _at(0.0), nearer, CAMERA)
    assert (brought[:, :32] == 7).all() and np.array_equal(brought[:, 32:], image[:, 32:])
    assert share == pytest.approx(0.5)


def test_a_pixel_the_render_leaves_transparent_keeps_the_render(neighbours):
    image, render = _texture(), np.full((48, 64, 3), 7, dtype=np.uint8)
    opacity = OPAQUE.copy()
    opacity[:10] = 0.2
    brought, _ = neighbours.brought_to(CAMERA, _at(0.0), DEPTH, opacity, render, image, _at(0.0), DEPTH, CAMERA)
    assert (brought[:10] == 7).all() and np.array_equal(brought[10:], image[10:])


def test_the_nearest_other_view_skips_the_view_itself(neighbours):
    views = [SimpleNamespace(name=str(x), c2w=_at(x)) for x in (0.0, 0.3, -0.1, 2.0)]
    view, degrees, distance = neighbours.nearest_other(_at(0.0), views, reference_length=1.0)
    assert view.name == "-0.1" and degrees == pytest.approx(0.0) and distance == pytest.approx(0.1)
    with pytest.raises(ValueError, match="no other view"):
        neighbours.nearest_other(_at(0.0), views[:1], reference_length=1.0)


def test_optical_flow_alignment_undoes_a_shift(neighbours):
    import cv2

    smooth = cv2.GaussianBlur(_texture(), (0, 0), 2.0)  # texture the flow can follow
    shifted = np.roll(smooth, 2, axis=1)
    aligned = neighbours.aligned_onto(smooth, shifted)
    inner = (slice(8, -8), slice(8, -8))
    assert psnr(smooth[inner], aligned[inner]) > psnr(smooth[inner], shifted[inner]) + 10, (
        f"aligned {psnr(smooth[inner], aligned[inner]):.1f} dB, shifted {psnr(smooth[inner], shifted[inner]):.1f} dB")
