"""Which scenes the kernel helper loads: one of each family the session reaches after its first render, never
a ``module:function`` scene (the helper runs no user code)."""

from __future__ import annotations

import pytest

from pytest_n2r.plugin.precompile import apart_specs, family, helper_specs
from pytest_n2r.plugin.scenes import SceneSpec

WALL, OBJECT = SceneSpec("wall", "demo", "demo:wall"), SceneSpec("object", "demo", "demo:object")
WALL_FIELD = SceneSpec("wall-field", "demo", "demo:wall-field")
OBJECT_FIELD = SceneSpec("object-field", "demo", "demo:object-field")
FOX, SPLATS = SceneSpec("fox", "file", "/s/fox.n2r"), SceneSpec("room", "file", "/s/room.PLY")
USER = SceneSpec("mine", "python", "mymodule:scene")


def test_families_follow_the_spec():
    assert [family(s) for s in (WALL, OBJECT, WALL_FIELD, FOX, SPLATS, USER)] == \
        ["demo", "demo", "demo-field", "file.n2r", "file.ply", None]


def test_the_helper_gets_one_scene_of_each_other_family_in_order():
    planned = [WALL, OBJECT, WALL_FIELD, OBJECT_FIELD, USER, FOX, SPLATS]
    assert helper_specs(planned, WALL) == [WALL_FIELD, FOX, SPLATS]
    assert helper_specs(planned, FOX) == [WALL, WALL_FIELD, SPLATS]
    assert helper_specs(planned, None) == [WALL, WALL_FIELD, FOX, SPLATS]


def test_nothing_for_the_helper_when_every_scene_shares_the_first_family():
    assert helper_specs([WALL, OBJECT], WALL) == []
    assert helper_specs([USER], USER) == []
    assert helper_specs([], None) == []


def test_the_helper_compiles_apart_the_scenes_of_the_first_family_when_it_can():
    planned = [WALL, WALL_FIELD, OBJECT, USER, FOX]
    assert apart_specs(planned, WALL) == [WALL, OBJECT], "the exact demo scenes' masks were not left to the helper"
    assert apart_specs(planned, WALL_FIELD) == [], "a fitted twin was loaded for nothing"
    assert apart_specs(planned, FOX) == [] and apart_specs(planned, USER) == [] and apart_specs(planned, None) == []


@pytest.mark.parametrize(("value", "starts"), [("yes", True), ("no", False)])
def test_precompile_no_leaves_the_session_without_a_helper(pytester, value, starts):
    from pytest_n2r.plugin import _build_session

    session = _build_session(pytester.parseconfig("--n2r-precompile", value))
    assert (session.on_first_render is not None) == starts, \
        f"--n2r-precompile {value}: the session {'would not' if starts else 'would'} start the kernel helper"
