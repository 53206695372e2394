"""Nothing to compare is never a pass: a SUT that gives no output, or the same output whatever the image,
fails its relation with a message that says so (issue 15, point 1)."""

from __future__ import annotations

import numpy as np
import pytest

from pytest_n2r import InvalidArgument, transforms
from pytest_n2r.metrics import MetricResult, interest_point_spread, repeatability
from pytest_n2r.relation import MAX_UNDEFINED, Relation, RelationFailure, RunSettings, Validity, check_relation
from pytest_n2r.relation.validity import Verdict
from tests.plugin.fakemetrics import AbsDifference
from tests.plugin.fakescene import PlaneScene

SETTINGS = RunSettings(examples=12, database=None, derandomize=True)


def no_keypoints(rgb: np.ndarray) -> np.ndarray:
    return np.zeros((0, 2), np.float32)


def same_grid(step: float):
    """A content-independent detector: the same grid of points on every image."""
    def detect(rgb: np.ndarray) -> np.ndarray:
        h, w = rgb.shape[:2]
        u, v = np.meshgrid(np.arange(step / 2, w, step), np.arange(step / 2, h, step))
        return np.stack([u.ravel(), v.ravel()], axis=1)
    return detect


@pytest.mark.parametrize("metric", [repeatability(px=2), interest_point_spread(radius=8)], ids=repr)
def test_an_empty_detector_fails_with_nothing_to_test(metric):
    relation = Relation.build(metric, eps=0.5, transform=transforms(yaw=3))
    with pytest.raises(RelationFailure, match="the SUT produced nothing to test") as info:
        check_relation(PlaneScene(), no_keypoints, relation, settings=SETTINGS)
    record = info.value.record
    assert record.outcome == "failed" and not record.valid_examples and record.undefined > 0
    assert "the SUT found no keypoint in either view" in str(info.value)
    assert all(e.status == "undefined" for e in record.examples) and record.examples
    camera = record.examples[0].camera
    assert f"rendered at {camera['width']}x{camera['height']} pixels" in str(info.value), (
        f"the message should name the size the SUT saw (a detector finds nothing in small images):\n{info.value}")


class _SometimesUndefined(AbsDifference):
    """Undefined on every ``every``-th pair."""

    def __init__(self, every: int):
        self.every, self.calls = every, 0

    def compute(self, out_source, out_follow, source=None, follow=None):
        self.calls += 1
        if self.calls % self.every == 0:
            return MetricResult.undefined(self.name, "no output this time")
        return super().compute(out_source, out_follow, source, follow)


@pytest.mark.parametrize("every, fails", [(7, False), (1, True)])
def test_undefined_draws_are_counted_and_a_mostly_undefined_relation_fails(every, fails):
    # yaw of 0.5° or more: smaller turns (the pose grid's ±0.001°) leave a 96x72 render's pixels as they were
    relation = Relation.build(_SometimesUndefined(every), eps=255, transform=transforms(yaw=(0.5, 3)))
    if fails:
        with pytest.raises(RelationFailure, match=r"nothing to test: .* undefined on \d+ of \d+ evaluated draws"):
            check_relation(PlaneScene(), mean_colour, relation, settings=SETTINGS)
        return
    record = check_relation(PlaneScene(), mean_colour, relation, settings=SETTINGS)
    share = record.undefined / (len(record.valid_examples) + record.undefined)
    assert record.outcome == "passed" and 0 < share <= MAX_UNDEFINED and len(record.valid_examples) == 12
    assert f"{record.undefined} undefined ({record.undefined} no output this time)" in record.summary_line()
    assert record.undefined_reasons == {"no output this time": record.undefined}


def mean_colour(rgb: np.ndarray) -> float:
    return float(rgb.mean())


@pytest.mark.parametrize("metric, eps", [(repeatability(px=2), 0.5), (interest_point_spread(radius=8), 0.5)],
                         ids=["repeatability", "spread"])
def test_a_content_independent_detector_fails_a_relation_with_yaw_of_5_degrees_or_more(metric, eps):
    relation = Relation.build(metric, eps=eps, transform=transforms(yaw=(5, 10)))
    with pytest.raises(RelationFailure) as info:
        check_relation(PlaneScene(), same_grid(8), relation, settings=SETTINGS)
    assert info.value.record.outcome == "failed"


def test_a_moved_camera_that_leaves_the_captured_region_is_told_of_look_at():
    relation = Relation.build(repeatability(px=2), eps=0.5, transform=transforms(x=(8, 9)), examples=5)
    with pytest.raises(InvalidArgument, match=r"narrow the bounds \(or use look_at=True, which turns a moved camera "):
        check_relation(PlaneScene(), same_grid(16), relation, settings=SETTINGS)
    already = Relation.build(repeatability(px=2), eps=0.5, transform=transforms(x=(8, 9), look_at=True), examples=5)
    with pytest.raises(InvalidArgument) as info:
        check_relation(PlaneScene(), same_grid(16), already, settings=SETTINGS)
    assert "narrow the bounds so" in str(info.value) and "use look_at=True" not in str(info.value), str(info.value)


class _UndefinedFirst(AbsDifference):
    """Undefined on every odd pair, the first included: half of the evaluated draws, never more at the end."""

    def __init__(self):
        self.calls = 0

    def compute(self, out_source, out_follow, source=None, follow=None):
        self.calls += 1
        if self.calls % 2 == 1:
            return MetricResult.undefined(self.name, "no output this time")
        return super().compute(out_source, out_follow, source, follow)


def test_a_relation_half_undefined_is_not_given_up_on_a_passing_majority():
    """The search stopped as soon as the running share of undefined draws passed one half (12 of 23 here), and
    the relation failed 'nothing to test' although its end share was one half, which passes."""
    relation = Relation.build(_UndefinedFirst(), eps=255, transform=transforms(yaw=(0.5, 3)))
    record = check_relation(PlaneScene(), mean_colour, relation, settings=SETTINGS)
    assert record.outcome == "passed" and len(record.valid_examples) == 12 and record.undefined == 12, (
        record.summary_line())


def test_a_follow_up_with_the_source_pixels_is_undefined_not_a_pass():
    """Black patches on a black view leave its pixels as they were: a SUT that flips its class on any pixel change
    passed every such pair before (20 of 20 "valid" examples, the SUT seeing one image)."""
    import hashlib

    from pytest_n2r.metrics import class_invariance
    from pytest_n2r.strategies import black_patches

    def fragile(rgb: np.ndarray) -> np.ndarray:  # the class is a hash of the pixels
        scores = np.full(10, 0.05)
        scores[int(hashlib.sha256(rgb.tobytes()).hexdigest(), 16) % 10] = 0.55
        return scores

    relation = Relation.build(class_invariance(), 0.0, black_patches(max_size=0.08))
    with pytest.raises(RelationFailure, match="nothing was tested") as info:
        check_relation(PlaneScene(half_width=1e-6), fragile, relation, settings=SETTINGS)  # every render black
    record = info.value.record
    assert not record.valid_examples, f"pairs of one image counted as tests: {record.valid_examples}"
    assert record.undefined_reasons, record
    assert "the follow-up's pixels equal the source's, byte for byte" in str(info.value)
    assert "the changes drawn left the pictures as they were" in str(info.value).lower(), str(info.value)


class _UndefinedOn(AbsDifference):
    """Undefined on the pairs whose call number (from 1) modulo ``period`` is in ``on``."""

    def __init__(self, period: int, on: tuple[int, ...]):
        self.period, self.on, self.calls = period, on, 0

    def compute(self, out_source, out_follow, source=None, follow=None):
        self.calls += 1
        if self.calls % self.period in self.on:
            return MetricResult.undefined(self.name, "no output this time")
        return super().compute(out_source, out_follow, source, follow)


class _RejectMost(Validity):
    """Every follow-up but each third is invalid, whatever it shows."""

    def __init__(self):
        super().__init__(max_empty_increase=1.0, min_coverage=0.0)
        object.__setattr__(self, "checks", 0)

    def check(self, view, scene, source=None, cameras=None):
        object.__setattr__(self, "checks", self.checks + 1)
        return Verdict(True) if self.checks % 3 == 0 else Verdict(False, "empty view", "rejected by the test")


def test_rejected_draws_do_not_dilute_the_share_of_undefined_ones():
    """The undefined share is of the draws the metric evaluated (valid and undefined): over all draws, rejected ones
    diluted it, and a relation whose SUT gave nothing to compare on two thirds of its evaluated draws passed."""
    relation = Relation.build(_UndefinedOn(3, (1, 2)), eps=255, transform=transforms(yaw=(0.5, 3)),
                              validity=_RejectMost())
    with pytest.raises(RelationFailure, match="the SUT produced nothing to test") as info:
        check_relation(PlaneScene(), mean_colour, relation, settings=SETTINGS)
    record = info.value.record
    evaluated = len(record.valid_examples) + record.undefined
    assert record.undefined / evaluated > MAX_UNDEFINED, record.summary_line()
    assert record.rejected and record.undefined / len(record.examples) <= MAX_UNDEFINED, (
        f"the test needs enough rejected draws to bring the share of all draws under the limit: "
        f"{record.summary_line()}")


def test_a_relation_undefined_on_55_percent_of_its_draws_fails():
    """More than :data:`MAX_UNDEFINED` (one half) of the evaluated draws undefined fails "nothing to test": with the
    limit at 0.6 a SUT that gave nothing to compare on 5 draws of 9 passed."""
    relation = Relation.build(_UndefinedOn(9, (0, 1, 3, 5, 7)), eps=255, transform=transforms(yaw=(0.5, 3)))
    with pytest.raises(RelationFailure, match=r"nothing to test: .* undefined on \d+ of \d+ evaluated draws") as info:
        check_relation(PlaneScene(), mean_colour, relation, settings=SETTINGS)
    record = info.value.record
    share = record.undefined / (len(record.valid_examples) + record.undefined)
    assert MAX_UNDEFINED < share < 0.6, f"the test needs a share between one half and 0.6, got {share:.0%}"
