"""The follow-up protocol: pose changes carry their units (through combinators too), mutations change the
source render in place, both are recorded and explained the same way, and pose-change families draw for
Hypothesis and for the study alike."""

from __future__ import annotations

import math
import re
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


def test_a_family_samples_its_components_in_alphabetical_order_whatever_order_its_bounds_came_in():
    """``sample`` draws one uniform per bounded component in alphabetical order of the names, so ``n2r study`` draws
    the same pose changes for a seed: in the order of the bounds dict, a family built with its bounds in another
    order (or a new release that orders them otherwise) drew other pose changes from the same seed."""
    bounds = {"yaw": (-10.0, 10.0), "x": (-0.2, 0.2), "pitch": (-3.0, 5.0)}
    orders = [dict(sorted(bounds.items())), bounds, dict(reversed(list(bounds.items())))]
    drawn = [PoseChangeFamily(order).sample(np.random.default_rng(0)) for order in orders]
    assert drawn[0] == drawn[1] == drawn[2], f"the order of the bounds changed the draws: {drawn}"
    rng = np.random.default_rng(0)
    pitch, x, yaw = (float(rng.uniform(*bounds[axis])) for axis in ("pitch", "x", "yaw"))
    expected = PoseChange.of(Transform(pitch=pitch, yaw=yaw, x=x))
    assert PoseChangeFamily.of(pitch=(-3, 5), yaw=10, x=0.2).sample(np.random.default_rng(0)) == expected, (
        "the draws of seed 0 are not pitch, x, yaw in turn")


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


def _user_mutation(name: str | None, module: str, qualname: str = "Shade", **fields_: object) -> type[Mutation]:
    """A concrete mutation class of a user's own, made as if ``module`` defined it."""
    body: dict[str, object] = {"__module__": module, "__qualname__": qualname, "__annotations__": {"level": int},
                               "level": 0, "is_identity": property(lambda self: False),
                               "_apply": lambda self, rgb: rgb, "describe": lambda self: "shade", **fields_}
    if name is not None:
        body["name"] = name
    return dataclass(frozen=True, repr=False)(type(qualname, (Mutation,), body))


def _refused(make, error: type[Exception], pattern: str, wrong: str) -> None:
    """``make()`` raises ``error`` with a message matching ``pattern``; else the test fails saying ``wrong``."""
    try:
        make()
    except error as exc:
        assert re.search(pattern, str(exc)), f"the message does not match {pattern!r}: {exc}"
        return
    pytest.fail(wrong)


def test_a_taken_mutation_name_is_refused_unless_the_same_class_is_defined_again():
    first = _user_mutation("test_shade", "tests.a.test_x")
    _refused(lambda: _user_mutation("test_shade", "tests.b.test_y"), InvalidArgument,
             r"tests\.b\.test_y\.Shade\.name='test_shade' is already the name of tests\.a\.test_x\.Shade",
             "a second class named like another user's mutation was accepted")
    assert n2r.mutation_from_dict({"name": "test_shade", "level": 1}) == first(1), \
        "a second class with a taken name replaced the first in the registry"
    again = _user_mutation("test_shade", "tests.a.test_x")  # its module reloaded: the new class takes the name
    assert type(n2r.mutation_from_dict({"name": "test_shade", "level": 1})) is again


def test_a_mutation_without_a_name_is_refused_when_drawn_not_where_defined():
    """A nameless mutation failed with a bare AttributeError inside Hypothesis when drawn; refusing it where it was
    defined refused a concrete base of named mutations, a common pattern that is never drawn itself."""
    nameless = _user_mutation(None, "tests.a.test_x", "Nameless")
    named = dataclass(frozen=True, repr=False)(type("RedTint", (nameless,), {"__module__": "tests.a.test_x",
                                                                             "name": "test_red_tint"}))
    assert named(3).as_dict() == {"name": "test_red_tint", "level": 3}, "a named subclass of a nameless base"
    _refused(lambda: nameless(3).as_dict(), InvalidArgument,
             r"Nameless has no name: a Mutation that is drawn needs a short name", "a nameless mutation was recorded")


def test_numpy_scalars_in_a_mutation_are_written_as_plain_numbers():
    import json

    cls = _user_mutation("test_numpy_fields", "tests.a.test_x", "NumpyFields", gain=0.0,
                         __annotations__={"level": int, "gain": float, "extra": object}, extra=None)
    plain = cls(np.int64(3), np.float32(0.5), (np.uint8(7), [np.bool_(True)])).as_dict()
    assert type(plain["level"]) is int and type(plain["gain"]) is float, f"numpy scalars were not made plain: {plain}"
    assert json.loads(json.dumps(plain)) == {"name": "test_numpy_fields", "level": 3, "gain": 0.5,
                                             "extra": [7, [True]]}, f"numpy scalars were not made plain: {plain!r}"
    with pytest.raises(InvalidType, match=r"NumpyFields\.extra=array\(\[1, 2\]\) cannot be written to a record"):
        cls(1, 0.5, np.array([1, 2])).as_dict()
