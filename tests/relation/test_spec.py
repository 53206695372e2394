"""Building a relation: every argument checked and named; fixed transforms and presets accepted."""

from __future__ import annotations

import pytest
from hypothesis import find

from pytest_n2r import InvalidArgument, InvalidType, Transform
from pytest_n2r.relation import Relation, RelationFailure, RunSettings, check_relation
from pytest_n2r.strategies import transforms
from tests.plugin.fakemetrics import AbsDifference, SameLabel
from tests.plugin.fakescene import PlaneScene

FAST = RunSettings(examples=10, database=None)


def test_relation_build_names_bad_arguments():
    with pytest.raises(InvalidType, match="eps='0.1' must be a number"):
        Relation.build(AbsDifference(), "0.1", transforms(yaw=3))
    with pytest.raises(InvalidArgument, match="examples=0 must be a whole number >= 1"):
        Relation.build(AbsDifference(), 0.1, transforms(yaw=3), examples=0)
    with pytest.raises(InvalidArgument, match="views='test'"):
        Relation.build(AbsDifference(), 0.1, transforms(yaw=3), views="test")
    with pytest.raises(InvalidType, match="metric=<lambda> must be a pytest_n2r.metrics.Metric|metric=.*function"):
        Relation.build(lambda a, b: 0, 0.1, transforms(yaw=3))
    with pytest.raises(InvalidType, match="transform=5 must be a strategy"):
        Relation.build(AbsDifference(), 0.1, 5)
    assert find(Relation.build(AbsDifference(), 0, Transform(yaw=2)).transform, lambda t: True) == Transform(yaw=2)


@pytest.mark.parametrize("still", [Transform(), Transform(yaw=360), Transform(roll=180, pitch=180, yaw=180)],
                         ids=repr)
def test_a_fixed_transform_that_does_not_move_the_camera_tests_nothing(still):
    # R_y(180) R_x(180) R_z(180) is the identity too: every follow-up is its source view, a pair of one image
    relation = Relation.build(SameLabel(), 0.5, still, examples=3)
    with pytest.raises(RelationFailure, match=r"nothing was tested: .* the follow-up's pixels equal the source's"):
        check_relation(PlaneScene(), lambda rgb: 0, relation, settings=FAST)


def test_a_fixed_transform_and_a_preset_are_accepted():
    scene = PlaneScene()
    for transform in (Transform(yaw=1), "tau1"):
        relation = Relation.build(SameLabel(), 0.5, transform, examples=3)
        record = check_relation(scene, lambda rgb: 0, relation, settings=FAST)
        assert record.outcome == "passed"
