"""Source-view strategies: splits, shrinking to the first view, picks resolved by a scene, the trajectory."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import find, given, settings
from hypothesis import strategies as st

from pytest_n2r import InvalidArgument, InvalidType, Transform
from pytest_n2r import strategies as n2r
from pytest_n2r.scene import SceneView
from pytest_n2r.scene.splits import scene_views
from pytest_n2r.scene.trajectory import trajectory_view

from ..plugin.fakescene import PlaneScene


def test_views_name_a_bad_split_or_flag():
    with pytest.raises(InvalidArgument, match="split='test' is not a split"):
        n2r.views(split="test")
    with pytest.raises(InvalidType, match="interpolate=1 must be True or False"):
        n2r.views(interpolate=1)
    with pytest.raises(InvalidType, match="scene='plane' must be a pytest_n2r.Scene"):
        n2r.views("plane")


def test_views_shrink_to_the_first_view_and_picks_resolve_through_the_scene():
    scene = PlaneScene(n_views=4)
    assert find(n2r.views(scene), lambda v: True).name == "view1"
    pick = find(n2r.views(), lambda v: True)
    source, _ = scene.pair(pick, Transform(yaw=1))
    np.testing.assert_array_equal(source.c2w, scene.views[1].c2w)


@settings(max_examples=20)
@given(data=st.data())
def test_views_of_a_split_are_the_scenes_own_views(data):
    scene = PlaneScene(n_views=4)
    view = data.draw(n2r.views(scene, split="train"))
    assert view in scene.views and view.split == "train"


@settings(max_examples=20)
@given(data=st.data())
def test_interpolating_views_draws_poses_between_neighbours(data):
    scene = PlaneScene(n_views=3)
    view = data.draw(n2r.views(scene, interpolate=True))
    ys = [v.c2w[1, 3] for v in scene.views]
    assert min(ys) <= view.c2w[1, 3] <= max(ys)


@settings(max_examples=20)
@given(pick=n2r.views(interpolate=True))
def test_an_interpolated_pick_resolves_to_the_trajectory_view_of_the_same_segment(pick):
    scene = PlaneScene(n_views=6)
    view = scene.view(pick)
    if pick.t:
        expected = trajectory_view(scene_views(scene, "heldout"), pick.index, pick.t)
        np.testing.assert_array_equal(view.c2w, expected.c2w)
        assert view.split == "interpolated", f"{pick} resolved to {view.name} of split {view.split!r}"
    else:
        assert view in scene.views and view.split == "heldout", f"{pick} resolved to {view.name} ({view.split})"


def _in_split(view, scene, split: str) -> bool:
    """Whether ``view`` is a captured view of ``split`` or a pose between two consecutive ones."""
    names = [v.name for v in scene_views(scene, split)]
    if view.split != "interpolated":
        return view.name in names
    start, end = view.name.split("@")[0].split("~")
    return start in names and end in names and names.index(end) == names.index(start) + 1


@settings(max_examples=50)
@given(data=st.data(), split=st.sampled_from(["heldout", "train"]))
def test_interpolated_views_keep_to_the_requested_split(data, split):
    scene = PlaneScene(n_views=6)  # train: view0, view2, view4; held out: view1, view3, view5
    view = data.draw(n2r.views(scene, split=split, interpolate=True))
    assert _in_split(view, scene, split), f"split={split!r} drew {view.name} (split {view.split!r})"
    pick = data.draw(n2r.views(split=split, interpolate=True))
    resolved = scene.view(pick)
    assert _in_split(resolved, scene, split), f"split={split!r} resolved {pick} to {resolved.name} ({resolved.split})"


@pytest.mark.parametrize("scene_given", [True, False])
def test_an_interpolated_held_out_draw_shrinks_to_a_held_out_view(scene_given):
    scene = PlaneScene(n_views=6)
    strategy = n2r.views(scene if scene_given else None, split="heldout", interpolate=True)
    drawn = find(strategy, lambda v: True)
    view = drawn if scene_given else scene.view(drawn)
    assert (view.name, view.split) == ("view1", "heldout"), (
        f"the minimal held-out draw is {view.name} of split {view.split!r}, not the first held-out view")


def test_views_sharing_a_name_are_each_drawn():
    """Views were drawn by name and looked up again, so of two views of one name only the first was ever drawn.
    (A Scene now refuses two views of one name; this scene's list was changed after it was set.)"""
    scene = PlaneScene(n_views=4)  # held out: view1, view3
    twin = scene.views[3]
    scene.views[3] = SceneView(twin.index, "view1", twin.camera, twin.c2w, twin.split)
    drawn = []

    @settings(max_examples=60, database=None)
    @given(view=n2r.views(scene))
    def collect(view):
        drawn.append(view)

    collect()
    assert any(v is scene.views[1] for v in drawn) and any(v is scene.views[3] for v in drawn), (
        f"drew {sorted({(v.index, v.name) for v in drawn})}; expected both views named 'view1' (indices 1 and 3)")


def test_a_scene_with_one_view_has_no_trajectory_and_draws_its_view():
    scene = PlaneScene(n_views=1)
    assert find(n2r.views(scene, interpolate=True), lambda v: True) is scene.views[0]
