"""The nearest other photo brought to a view's pose (pytest_n2r.relation.floor.nearby): it lands where the two
depths say, keeps the render where the other view does not see the point, and is never the view itself."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from pytest_n2r.errors import InvalidArgument
from pytest_n2r.geometry import Camera
from pytest_n2r.relation.floor.nearby import brought_to_view, nearest_fitted_view
from pytest_n2r.render.view import RenderedView

CAMERA = Camera(64, 48, fx=50.0, fy=50.0, cx=31.5, cy=23.5)
RENDER = np.full((48, 64, 3), 7, dtype=np.uint8)


def _at(x: float) -> np.ndarray:
    c2w = np.eye(4)
    c2w[0, 3] = x
    return c2w


def _wall(x: float, depth: float = 2.0, opacity: float = 1.0) -> RenderedView:
    """The view from ``(x, 0, 0)`` of a wall ``depth`` in front, facing the camera."""
    return RenderedView(CAMERA, _at(x), rgb=RENDER, depth=np.full((48, 64), depth, dtype=np.float32),
                        opacity=np.full((48, 64), opacity, dtype=np.float32))


def _texture() -> np.ndarray:
    return np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)


def test_an_image_brought_to_its_own_pose_is_itself():
    image = _texture()
    brought, share = brought_to_view(_wall(0.0), image, _wall(0.0))
    assert share == 1.0, f"every pixel sees itself, got a share of {share}"
    assert np.array_equal(brought, image), f"max difference {np.abs(brought.astype(int) - image).max()}"


def test_a_sideways_step_moves_the_wall_by_the_disparity():
    # The other camera is 0.16 units right: a point on the wall lands fx * 0.16 / 2 = 4 px further left in it.
    image = _texture()
    brought, share = brought_to_view(_wall(0.0), image, _wall(0.16))
    assert np.array_equal(brought[:, 4:], image[:, :-4]), "the wall's texture did not land 4 px to the right"
    assert (brought[:, :4] == 7).all(), "pixels the other camera does not see must keep the render's colour"
    assert share == pytest.approx(60 / 64)


def test_a_point_the_other_view_sees_something_nearer_at_keeps_the_render():
    image, other = _texture(), _wall(0.0)
    other.depth[:, :32] = 1.0  # an occluder in front of the left half of the wall, as the other view sees it
    brought, share = brought_to_view(_wall(0.0), image, other)
    assert (brought[:, :32] == 7).all() and np.array_equal(brought[:, 32:], image[:, 32:])
    assert share == pytest.approx(0.5)


def test_a_pixel_with_no_surface_in_either_view_keeps_the_render():
    image, view, other = _texture(), _wall(0.0), _wall(0.0)
    view.opacity[:10] = 0.2
    other.opacity[-10:] = 0.2
    brought, share = brought_to_view(view, image, other)
    assert (brought[:10] == 7).all() and (brought[-10:] == 7).all()
    assert np.array_equal(brought[10:-10], image[10:-10]) and share == pytest.approx(28 / 48)


def test_an_image_of_another_size_than_its_view_is_refused():
    with pytest.raises(ValueError, match="image is 32x48 pixels but its view's depth is 64x48"):
        brought_to_view(_wall(0.0), _texture()[:, :32], _wall(0.0))


def test_an_image_view_rendered_without_depth_is_named():
    """The image's view is read through its depth: without it the call failed with ``'NoneType' object has no
    attribute 'shape'`` instead of naming the argument and what it lacks."""
    no_depth = RenderedView(CAMERA, _at(0.0), rgb=RENDER)
    with pytest.raises(InvalidArgument, match=r"image_view was rendered without depth, opacity"):
        brought_to_view(_wall(0.0), _texture(), no_depth)


def test_the_nearest_fitted_view_is_another_usable_training_view():
    views = [SimpleNamespace(name=name, split=split, c2w=_at(x), image=image)
             for name, split, x, image in (("self", "train", 0.0, 1), ("held", "heldout", 0.05, 1),
                                           ("bare", "train", 0.1, None), ("near", "train", -0.3, 1),
                                           ("far", "train", 2.0, 1))]
    scene = SimpleNamespace(name="s", views=views, reference_length=2.0)
    view, degrees, distance = nearest_fitted_view(scene, _at(0.0), lambda v: v.image is not None)
    assert (view.name, degrees, distance) == ("near", 0.0, pytest.approx(0.15))
    turned = _at(0.0)
    turned[:3, :3] = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]  # a quarter turn about y
    views[3].c2w = turned
    view, degrees, _ = nearest_fitted_view(scene, _at(0.0), lambda v: v.image is not None)
    assert view.name == "far", "a quarter turn (1.57 rad) counts more than 1 reference length away"
    with pytest.raises(ValueError, match="scene 's' has no other fitted view"):
        nearest_fitted_view(scene, _at(0.0), lambda v: v.name == "self")
