"""The size of a rendered demo capture (``capture_scene``, ``check_size``)."""

from __future__ import annotations

import numpy as np
import pytest

from pytest_n2r.demo import ground_truth
from pytest_n2r.demo.rendered_capture import check_size
from pytest_n2r.errors import InvalidArgument, InvalidType


@pytest.mark.parametrize("size, expected", [(96, (96, 54)), ((64, 36), (64, 36)), ((np.int64(32), 18), (32, 18))])
def test_a_size_is_the_longer_side_or_a_pair_of_ints(size, expected):
    camera = check_size(size, ground_truth("wall").views[0].camera)
    assert (camera.width, camera.height) == expected, (size, camera)


@pytest.mark.parametrize("size, error, message", [
    ((480.7, 270.2), InvalidType, r"size=\(480\.7, 270\.2\) must be an int .* or a \(width, height\) pair of ints"),
    ((True, 64), InvalidType, r"pair of ints"),
    ((64, 36, 3), InvalidType, r"pair of ints"),
    ("64x36", InvalidType, r"pair of ints"),
    ((4, 36), InvalidArgument, r"gives 4x36 pixels; expected at least 8x8"),
])
def test_a_size_that_is_no_pixel_count_is_refused_not_truncated(size, error, message):
    """``(480.7, 270.2)`` rendered at 480x270: the fractions were dropped without a word."""
    with pytest.raises(error, match=message):
        check_size(size, ground_truth("wall").views[0].camera)


@pytest.mark.parametrize("name", ["wall", "object"])
def test_each_capture_point_is_a_pixel_of_a_training_view_on_its_surface_within_twice_the_reference_length(name):
    """As the docstring says: a point is back-projected from a pixel centre of a training view's 64-pixel depth map,
    lies on the surface that view sees first, at most twice the reference length in front of it. Points back-projected
    through the capture's camera instead of the depth map's, or far background kept, would give the fit wrong
    bounds."""
    from pytest_n2r.demo import capture
    from pytest_n2r.geometry import project

    scene = ground_truth(name)
    points = capture(name, size=96).points
    limit = 2 * scene.reference_length * (1 + 1e-6)
    found = np.zeros(len(points), bool)
    for view in scene.views:
        if view.split != "train":
            continue
        small, origin = view.camera.fit_within(64), view.c2w[:3, 3]
        uv, z = project(points, small, view.c2w)
        at_pixel = (np.abs(uv - np.rint(uv)) < 1e-3).all(axis=1) & (z > 0)
        t, _ = scene.cast(np.broadcast_to(origin, points.shape).copy(), points - origin)  # the point is at t = 1
        found |= at_pixel & (np.abs(t - 1) < 1e-5) & (z <= limit)
    assert found.all(), (
        f"{name}: {np.sum(~found)} of {len(points)} capture points are no pixel of a training view's 64-pixel depth "
        f"map on its first surface within {limit:.2f} units, e.g. {points[~found][0]}")


def test_a_view_neither_trained_on_nor_held_out_is_refused_by_name():
    """A scene's view may have any split (a trajectory's are ``interpolated``); a capture's are ``train`` or
    ``heldout``: such a view was put into the capture as a view of neither list, which the fit then ignored."""
    import dataclasses

    from pytest_n2r.demo import GroundTruthScene
    from pytest_n2r.demo.rendered_capture import capture_scene

    wall = ground_truth("wall")
    odd = dataclasses.replace(wall.views[0], split="interpolated")
    scene = GroundTruthScene("odd", list(wall.primitives), [odd, *wall.views[1:2]], light=(0, 0, 1), ambient=0.5,
                             background=(0, 0, 0), far=30.0)
    with pytest.raises(InvalidArgument, match=r"view 'wall_000.png' has split='interpolated'; .* 'train' or 'heldout'"):
        capture_scene(scene, size=16)
