"""Source-view selection with the scene: splits with their fallback, and views along the capture trajectory."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pytest_n2r import InvalidArgument, Transform
from pytest_n2r.scene.splits import SOURCE_SPLITS, scene_views
from pytest_n2r.scene.trajectory import interpolate_view, trajectory_view

from ..plugin.fakescene import PlaneScene


def test_views_split_and_fallback():
    scene = PlaneScene(n_views=4)
    assert [v.name for v in scene_views(scene, "heldout")] == ["view1", "view3"]
    assert [v.name for v in scene_views(scene, "train")] == ["view0", "view2"]
    assert len(scene_views(scene, "all")) == 4
    single = PlaneScene(n_views=1)  # only a train view: held-out falls back to every view
    assert [v.name for v in scene_views(single, "heldout")] == ["view0"]
    with pytest.raises(InvalidArgument, match="has no 'train' views; use split='all'"):
        scene_views(_only_heldout(), "train")
    with pytest.raises(InvalidArgument) as info:
        scene_views(scene, "test")
    assert str(info.value) == f"split='test' is not a split; expected one of {SOURCE_SPLITS}"


def _only_heldout() -> PlaneScene:
    scene = PlaneScene(n_views=2)
    scene.views = [scene.views[1]]
    return scene


def test_interpolated_views_lie_on_the_trajectory():
    scene = PlaneScene(n_views=3)
    a, b = scene.views[0], scene.views[1]
    mid = interpolate_view(a, b, 0.5)
    np.testing.assert_allclose(mid.c2w[:3, 3], (a.c2w[:3, 3] + b.c2w[:3, 3]) / 2)
    rotated = type(b)(b.index, b.name, b.camera, Transform(yaw=40).apply(b.c2w), b.split)
    quarter = interpolate_view(a, rotated, 0.25)
    np.testing.assert_allclose(quarter.c2w[:3, :3], Transform(yaw=10).rotation, atol=1e-12)
    assert interpolate_view(a, b, 0.0) is a
    assert (mid.name, mid.split, mid.camera) == ("view0~view1@0.50", "interpolated", a.camera)
    with pytest.raises(InvalidArgument, match=r"t=1.5 is out of range; expected a value in \[0, 1\]"):
        interpolate_view(a, b, 1.5)


def test_trajectory_segments_wrap_around_and_a_single_view_is_its_own_trajectory():
    views = list(PlaneScene(n_views=3).views)
    np.testing.assert_array_equal(trajectory_view(views, 3, 0.5).c2w, interpolate_view(views[1], views[2], 0.5).c2w)
    assert trajectory_view(views[:1], 7, 0.5) is views[0]


def test_an_interpolated_view_keeps_the_first_views_camera():
    a, b = PlaneScene(n_views=2).views
    b = dataclasses.replace(b, camera=b.camera.scaled(0.5))
    assert interpolate_view(a, b, 0.5).camera == a.camera


def test_trajectory_segments_past_the_last_wrap_to_the_first():
    views = list(PlaneScene(n_views=3).views)  # 2 segments: segment 2 is segment 0
    np.testing.assert_array_equal(trajectory_view(views, 2, 0.5).c2w, interpolate_view(views[0], views[1], 0.5).c2w)
