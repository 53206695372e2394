"""The follow-up protocol: pose changes carry their units (through combinators too), mutations change the
source render in place, both are recorded and explained the same way, and pose-change families draw for
Hypothesis and for the study alike."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest
from hypothesis import find, given, settings
from hypothesis import strategies as st

from pytest_n2r import InvalidArgument, InvalidType, Transform
from pytest_n2r import strategies as n2r
from pytest_n2r.geometry import Units
from pytest_n2r.geometry.look_at import look_at_transform
from pytest_n2r.strategies import FollowUp, Mutation, PoseChange, PoseChangeFamily, as_follow_up

from ..plugin.fakescene import PlaneScene

SCENE_UNITS = n2r.transforms(x=0.5, units="scene")
METRES = n2r.transforms(x=0.5, units="metres")


@pytest.mark.parametrize(
    "strategy",
    [SCENE_UNITS, SCENE_UNITS.map(lambda t: t), SCENE_UNITS.filter(lambda t: t.x != 0.123),
     st.one_of(SCENE_UNITS, SCENE_UNITS.filter(lambda t: True)), SCENE_UNITS.flatmap(st.just)],
    ids=["plain", "map", "filter", "one_of", "flatmap"],
)
def test_units_ride_on_the_drawn_value_through_combinators(strategy):
    @settings(max_examples=20, database=None)
    @given(tau=strategy)
    def check(tau):
        assert isinstance(tau, PoseChange) and isinstance(tau, Transform)
        assert tau.units is Units.SCENE, f"{strategy!r} drew {tau!r}"

    check()


def test_one_of_mixed_units_keeps_each_branchs_units():
    mixed = st.one_of(SCENE_UNITS, METRES)
    assert find(mixed, lambda t: t.units is Units.METRES).units is Units.METRES
    assert find(mixed, lambda t: t.units is Units.SCENE).units is Units.SCENE


def test_a_pose_change_is_a_transform_with_units():
    tau = PoseChange(yaw=5.0, x=0.1, units="scene")
    assert tau.units is Units.SCENE and tau.transform == Transform(yaw=5.0, x=0.1)
    assert tau != PoseChange(yaw=5.0, x=0.1) and PoseChange.of(Transform(yaw=1)) == PoseChange(yaw=1)
    assert tau.as_dict() == Transform(yaw=5.0, x=0.1).as_dict()  # components only: the units are separate
    assert tau.record_fields() == {"transform": tau.as_dict(), "units": "scene"}
    assert repr(PoseChange(yaw=2)) == "PoseChange(yaw=2.0)" and eval(repr(tau)) == tau
    assert tau.describe() == "yaw=+5.000°, x=+0.1 scene" and PoseChange(x=0.1).describe() == "x=+0.1 ref"
    np.testing.assert_array_equal(tau.apply(np.eye(4), 2.0), Transform(yaw=5.0, x=0.1).apply(np.eye(4), 2.0))
    with pytest.raises(InvalidArgument, match=r"units='furlongs' is not a unit; expected one of"):
        PoseChange(x=1, units="furlongs")


def test_inverting_and_chaining_pose_changes_keep_their_units():
    """PoseChange inherited Transform.inverse() and .then(), which returned a plain Transform: a change of 0.1
    scene units came back as 0.1 reference lengths."""
    tau = PoseChange(yaw=5.0, x=0.1, units="scene")
    inverse = tau.inverse()
    assert isinstance(inverse, PoseChange) and inverse.units is Units.SCENE, f"inverse {inverse!r} lost units='scene'"
    assert inverse.transform == tau.transform.inverse(), f"{inverse!r} is not the inverse of {tau!r}"
    both = tau.then(PoseChange(yaw=-5.0, units="scene"))
    assert isinstance(both, PoseChange) and both.units is Units.SCENE, f"{both!r} lost units='scene'"
    assert both.x == pytest.approx(0.1) and both.yaw == pytest.approx(0.0, abs=1e-12), f"{both!r}"
    assert tau.then(Transform(yaw=1.0)).units is Units.SCENE, "a plain Transform is read in the change's units"
    np.testing.assert_allclose(tau.then(inverse).matrix(), np.eye(4), atol=1e-12)
    with pytest.raises(InvalidArgument, match=r"cannot combine PoseChange\(yaw=5.0, x=0.1, units='scene'\) "
                                              r"\(translation in 'scene' units\) with PoseChange\(x=0.1\) "
                                              r"\(in 'reference' units\)"):
        tau.then(PoseChange(x=0.1))
    with pytest.raises(InvalidType, match=r"other='yaw=1' must be a pytest_n2r.Transform, not str"):
        tau.then("yaw=1")


def test_plain_transforms_are_pose_changes_in_reference_lengths_and_other_values_are_named():
    assert as_follow_up(Transform(yaw=3)) == PoseChange(yaw=3)
    tau, mutation = PoseChange(x=1, units="scene"), n2r.Brightness(10)
    assert as_follow_up(tau) is tau and as_follow_up(mutation) is mutation
    with pytest.raises(InvalidType, match=r"drew 'yaw=3' \(str\); expected a pose change"):
        as_follow_up("yaw=3")


def test_pose_changes_render_the_moved_camera_and_mutations_change_the_source_in_place():
    scene = PlaneScene()
    view = scene.views[1]
    source = scene.render(view.c2w, view.camera)
    rendered = []

    def render(c2w):
        rendered.append(c2w)
        return scene.render(c2w, view.camera)

    tau = PoseChange(yaw=2, x=0.5, units="scene")
    follow = tau.follow_view(source, scene, render)
    np.testing.assert_array_equal(follow.c2w, tau.apply(view.c2w, 1.0))
    assert tau.moves_camera and len(rendered) == 1
    mutated = n2r.Brightness(40).follow_view(source, scene, render)
    assert not n2r.Brightness.moves_camera and len(rendered) == 1, "a mutation renders nothing"
    np.testing.assert_array_equal(mutated.c2w, source.c2w)
    np.testing.assert_array_equal(mutated.rgb, n2r.Brightness(40).apply(source.rgb))


def test_failure_lines_say_the_follow_up_in_scene_units_and_metres():
    scene = PlaneScene()  # reference length 2.0, no known scale
    assert PoseChange(yaw=1, x=0.1).explain(scene, "") == [
        "  transform:  yaw=+1.000°, x=+0.1 ref  (minimal after shrinking)", "              = x=+0.2 scene units"]
    scene.metres_per_unit = 0.5
    assert PoseChange(y=-0.3, units="scene").explain(scene, "as drawn")[1] == \
        "              = y=-0.3 scene units = y=-0.15 m"
    assert n2r.Brightness(30).explain(scene, "") == [
        ("  follow-up:  the source render mutated by brightness +30 levels (+11.8% of full scale)  (minimal after "
        "shrinking)")], "a mutation is shrunk as a pose change is, and its line says so as a pose change's does"
    assert n2r.Brightness(30).explain(scene, "as drawn")[0].endswith("(as drawn)")


def test_a_pose_change_in_metres_is_refused_on_a_scene_without_scale_before_rendering():
    with pytest.raises(InvalidArgument, match="units='metres' needs a scene with a known scale"):
        PoseChange(x=0.1, units="metres").check_scene(PlaneScene())
    n2r.Brightness(3).check_scene(PlaneScene())  # a mutation fits every scene


def test_scene_pair_uses_the_units_the_pose_change_carries():
    scene = PlaneScene()
    view = scene.views[0]
    _, follow = scene.pair(view, PoseChange(x=0.5, units="scene"))
    np.testing.assert_allclose(follow.c2w[:3, 3] - view.c2w[:3, 3], view.c2w[:3, :3] @ [0.5, 0, 0])
    _, follow = scene.pair(view, Transform(x=0.5))  # a plain transform: reference lengths (2.0 here)
    np.testing.assert_allclose(follow.c2w[:3, 3] - view.c2w[:3, 3], view.c2w[:3, :3] @ [1.0, 0, 0])
    with pytest.raises(InvalidArgument, match="units='reference' contradicts tau=PoseChange"):
        scene.pair(view, PoseChange(x=0.5, units="scene"), units="reference")


@dataclass(frozen=True, repr=False)
class _Solarize(Mutation):
    threshold: int = 128
    name: ClassVar[str] = "test_solarize"

    @property
    def is_identity(self) -> bool:
        return self.threshold >= 256

    def _apply(self, rgb):
        return np.where(rgb >= self.threshold, 255 - rgb, rgb).astype(np.uint8)

    def describe(self) -> str:
        return f"solarize above {self.threshold}"


def test_a_mutation_of_ones_own_is_a_follow_up_rebuilt_from_its_record():
    mutation = _Solarize(100)
    assert isinstance(mutation, FollowUp)
    record = mutation.record_fields()
    assert record == {"transform": None, "mutation": {"name": "test_solarize", "threshold": 100}}
    assert n2r.mutation_from_dict(record["mutation"]) == mutation
    with pytest.raises(InvalidArgument, match="is the built-in Brightness's; give the mutation another name"):
        type("Mine", (Mutation,), {"name": "brightness", "__module__": "elsewhere"})


def _keeps_the_look_at_point(tau: Transform) -> bool:
    T = tau.matrix()
    p = T[:3, :3].T @ (np.array([0.0, 0.0, 1.0]) - T[:3, 3])  # the look-at point in the moved camera frame
    return p[2] > 0 and math.hypot(p[0], p[1]) < 1e-9


def test_a_family_draws_the_same_pose_changes_for_hypothesis_and_the_study():
    family = PoseChangeFamily.of(x=0.3, y=(-0.2, 0.1), look_at=True)
    assert repr(family.strategy()) == repr(n2r.transforms(x=0.3, y=(-0.2, 0.1), look_at=True))
    assert family.build({"x": 0.1, "y": -0.05}) == PoseChange.of(look_at_transform(x=0.1, y=-0.05))
    rng = np.random.default_rng(7)
    for _ in range(50):
        tau = family.sample(rng)
        assert -0.3 <= tau.x <= 0.3 and -0.2 <= tau.y <= 0.1 and tau.units is Units.REFERENCE
        assert _keeps_the_look_at_point(tau), f"{tau!r} loses the look-at point"
    assert family.sample(np.random.default_rng(1)) == family.sample(np.random.default_rng(1))

    @settings(max_examples=30, database=None)
    @given(tau=family.strategy())
    def drawn_by_hypothesis(tau):
        assert _keeps_the_look_at_point(tau), f"{tau!r} loses the look-at point"

    drawn_by_hypothesis()


def test_bad_family_arguments_are_named():
    with pytest.raises(InvalidArgument, match="look_at=True needs units='reference'"):
        PoseChangeFamily.of(x=0.1, units="scene", look_at=True)
    with pytest.raises(InvalidType, match="look_at=1 must be True or False"):
        PoseChangeFamily.of(look_at=1)
    with pytest.raises(InvalidArgument, match="roll, pitch, yaw, x, y and z are all 0"):
        PoseChangeFamily.of(units="scene")


def test_a_look_at_turn_past_a_full_turn_is_the_same_rotation_one_turn_back():
    """``yaw=-359`` with the compensation for ``x=0.5`` summed to -385.6°, refused naming a value never passed."""
    folded = look_at_transform(yaw=-359.0, x=0.5)
    np.testing.assert_allclose(folded.rotation, look_at_transform(yaw=1.0, x=0.5).rotation, atol=1e-12)
    assert -360.0 <= folded.yaw <= 360.0
    with pytest.raises(InvalidArgument, match=r"yaw=-361.0 is out of range"):
        look_at_transform(yaw=-361.0, x=0.5)
