"""When a rendered follow-up view is a fair input: empty views and views outside the captured region."""

from __future__ import annotations

import pytest

from pytest_n2r import InvalidArgument, Transform
from pytest_n2r.relation import Validity
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


def test_a_verdict_key_names_the_thresholds_the_renders_and_the_training_cameras():
    scene, source, follow = PlaneScene(), "1" * 64, "2" * 64
    key = Validity().verdict_key(scene, source, follow)
    assert key == Validity().verdict_key(PlaneScene(), source, follow)
    others = {Validity(min_coverage=0.7).verdict_key(scene, source, follow),
              Validity().verdict_key(scene, follow, source),
              Validity().verdict_key(PlaneScene(n_views=6), source, follow)}
    assert key not in others and len(others) == 3
