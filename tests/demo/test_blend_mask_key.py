"""A Blend mask's code keys its scene's content hash (and so its renders), not only its hand-written name."""

from __future__ import annotations

import numpy as np
import pytest

from pytest_n2r import GroundTruthScene
from pytest_n2r.demo import ground_truth
from pytest_n2r.demo.fitted import RECIPES, find_fitted, packaged_path
from pytest_n2r.demo.materials import Blend, Flat
from pytest_n2r.demo.primitives import Disc
from pytest_n2r.demo.scenes import _smoothstep, _views, default_camera, look_at


def _moss(a, b):
    return _smoothstep(0.4, 0.6, 0.5 + 0.5 * np.sin(1.3 * a) * np.sin(1.9 * b))


def _moss_edited(a, b):  # the same mask with other frequencies: 10273 of 14400 pixels differed, max 138
    return _smoothstep(0.4, 0.6, 0.5 + 0.5 * np.sin(4.1 * a) * np.sin(3.3 * b))


def _scene(mask) -> GroundTruthScene:
    floor = Disc(0.0, 6.0, Blend(Flat((0.8, 0.7, 0.6)), Flat((0.1, 0.5, 0.1)), mask, "moss"))
    poses = [look_at(np.array([x, -3.0, 1.5]), np.array([x, 0.0, 0.0])) for x in np.linspace(-1, 1, 3)]
    return GroundTruthScene("mossfloor", [floor], _views(poses, default_camera(160, 90), "m"),
                            light=(0.3, -1.0, 0.9), ambient=0.35, background=(0.05, 0.2, 0.3), far=30.0)


def test_two_blends_of_one_name_and_other_mask_functions_hash_apart():
    """A user's ``module:function`` scene whose mask function was edited under the same name took the old
    pictures from a warm render cache: the content hash named the mask by its name alone."""
    a, b = _scene(_moss), _scene(_moss_edited)
    assert a.content_hash != b.content_hash, "an edited mask of the same name kept the scene's content hash"
    assert _scene(_moss).content_hash == a.content_hash, "the same mask must keep the hash"


def test_a_builtin_mask_keeps_its_name_alone_and_the_shipped_twins_stay_current():
    """The demo package's own masks are named by their hand-written names only (their source is in every render
    key already); a fingerprint there would make the shipped fitted twins' recipe digests stale."""
    described = "".join(p.describe() for p in ground_truth("wall").primitives)
    assert ", growth-v1)" in described, "the wall's growth mask is no longer named by its name alone"
    for name in RECIPES:
        if packaged_path(name).is_file():
            assert find_fitted(name)[0] == packaged_path(name), f"the shipped {name} twin is stale"


def test_a_mask_without_a_module_is_named_by_its_name_not_an_error():
    """A mask made by ``exec`` in a namespace without ``__name__`` has no ``__module__``: describing it raised."""
    namespace: dict = {"np": np}
    exec("def moss(a, b):\n    return 0.5 + 0.0 * a * b\n", namespace)  # noqa: S102 - the case under test
    assert namespace["moss"].__module__ is None
    assert _scene(namespace["moss"]).content_hash, "no content hash for a scene of an exec'd mask"


def test_the_builtin_masks_are_what_their_names_stand_for():
    """A built-in mask is keyed by its hand-written name alone (above), so an edit that keeps the name keeps the scene's
    content hash and the shipped twins' recipe digests: the twins would pass for fits of a scene that changed. Editing a
    mask means a new name (``growth-v2``), a rebuilt twin and new values here."""
    from pytest_n2r.demo.scenes import _growth_mask, _road_mask

    a, b = np.meshgrid(np.linspace(-8, 8, 161), np.linspace(-2.6, 1.6, 43))
    growth = float(_growth_mask(a.ravel(), b.ravel()).mean())
    a, b = np.meshgrid(np.linspace(-25, 25, 201), np.linspace(-25, 25, 201))
    road = float(_road_mask(a.ravel(), b.ravel()).mean())
    assert (growth, road) == pytest.approx((0.33384189760293426, 0.09538379533572569), abs=1e-9), (
        f"growth-v1 covers {growth!r} of the wall, road-v1 {road!r} of the ground: a mask changed under its name")
