"""When a rendered follow-up view is a fair input: empty views and views outside the captured region."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r import Camera, InvalidArgument, SceneView, Transform
from pytest_n2r.geometry import project
from pytest_n2r.relation import Validity
from pytest_n2r.relation.validity import CameraStack
from tests.plugin.fakescene import PlaneScene


def test_validity_rejects_empty_and_uncovered_views():
    scene = PlaneScene()
    view = scene.views[1]
    outputs = ("rgb", "depth", "opacity")
    assert Validity().check(scene.render(view.c2w, view.camera, outputs), scene).valid
    empty = Validity().check(scene.render(Transform(yaw=50).apply(view.c2w), view.camera, outputs), scene)
    assert (empty.valid, empty.reason) == (False, "empty view"), empty
    source = scene.render(view.c2w, view.camera, outputs)
    half = scene.render(Transform(yaw=30).apply(view.c2w), view.camera, outputs)
    assert not Validity().check(half, scene, source).valid
    # a source that already shows that much emptiness (an object against the sky) makes the same view fair
    assert Validity(min_coverage=0).check(half, scene, half).valid
    # large plane: opacity stays 1, but the training cameras never saw that far out
    wide = PlaneScene(half_width=50.0)
    uncovered = Validity().check(wide.render(Transform(yaw=40).apply(view.c2w), view.camera, outputs), wide)
    assert (uncovered.valid, uncovered.reason) == (False, "outside the captured region"), uncovered


def test_validity_thresholds_are_checked():
    with pytest.raises(InvalidArgument, match=r"max_empty_increase=1.5 is out of range"):
        Validity(max_empty_increase=1.5)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_points=st.integers(0, 300), n_views=st.integers(1, 50))
def test_camera_stack_sees_what_projecting_into_each_camera_sees(seed, n_points, n_views):
    """The coverage check projects into all training cameras in one array operation; it must agree point for
    point with projecting into each camera apart (behind the camera, outside the image, on either side)."""
    rng = np.random.default_rng(seed)
    views = []
    for i in range(n_views):
        yaw, pitch = rng.uniform(-180, 180), rng.uniform(-60, 60)
        c2w = Transform(yaw=yaw, pitch=pitch, x=rng.normal(), y=rng.normal(), z=rng.normal()).apply(np.eye(4))
        width, height = int(rng.integers(8, 400)), int(rng.integers(8, 300))
        camera = Camera(width, height, rng.uniform(50, 500), rng.uniform(50, 500), rng.uniform(0, width),
                        rng.uniform(0, height))
        views.append(SceneView(index=i, name=f"v{i}", camera=camera, c2w=c2w, split="train"))
    points = rng.normal(scale=3.0, size=(n_points, 3))
    expected = np.zeros(n_points, dtype=bool)
    for view in views:
        uv, z = project(points, view.camera, view.c2w)
        w, h = view.camera.width, view.camera.height
        expected |= (z > 0) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= w - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= h - 0.5)
    seen = CameraStack.of(views).seen(points)
    assert np.array_equal(seen, expected), f"{int((seen != expected).sum())} of {n_points} points disagree"
