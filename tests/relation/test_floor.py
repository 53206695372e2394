"""The field floor (pytest_n2r.relation.floor): the SUT on the real photo vs on the render at the same pose."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pytest_n2r.demo import ground_truth, load_demo
from pytest_n2r.metrics import repeatability
from pytest_n2r.metrics.base import Metric
from pytest_n2r.metrics.keypoints import Repeatability
from pytest_n2r.relation.floor import FieldFloor, FloorStore, measure_floor, reference_kind
from pytest_n2r.relation.floor.reference import ShiftSample, floor_views, shift_sample
from pytest_n2r.render.size import RenderSize
from pytest_n2r.study import StudyConfig, resolve_sut, run_study
from tests.plugin.fakefield import BlurredPlane, corners


class Counting:
    """A SUT wrapper that counts its calls."""

    def __init__(self, fn):
        self.fn, self.calls = fn, 0

    def __call__(self, rgb):
        self.calls += 1
        return self.fn(rgb)


@pytest.fixture
def measured(monkeypatch):
    """How many floor samples the metric has computed since (0 after a floor taken from the store: a kept floor
    still runs the SUT on every image, to name its outputs)."""
    from pytest_n2r.relation.floor import measure

    count = [0]

    def counting(*args, **kwargs):
        count[0] += 1
        return shift_sample(*args, **kwargs)

    monkeypatch.setattr(measure, "shift_sample", counting)
    return count


def test_render_equal_to_photo_gives_a_zero_floor():
    floor = measure_floor(BlurredPlane(blur=0.0, width=160, height=120), corners, repeatability(px=2))
    assert floor.reference == "photo" and floor.n == 2, floor
    assert floor.value == 0.0 and not floor.above(0.0)


def test_a_soft_field_raises_the_floor_and_eps_below_it_warns():
    mild = measure_floor(BlurredPlane(blur=1.5, width=160, height=120), corners, repeatability(px=2))
    strong = measure_floor(BlurredPlane(blur=2.5, width=160, height=120), corners, repeatability(px=2))
    assert 0.05 < mild.value < strong.value, (mild.value, strong.value)
    assert mild.above(0.05) and not mild.above(0.5)
    assert "WARNING: eps 0.05 is below the field floor" in mild.describe(0.05)
    assert "WARNING" not in mild.describe(0.5) and "mean of 2 held-out views" in mild.describe(0.5)


def test_no_photos_means_no_floor_never_a_perfect_one():
    floor = measure_floor(BlurredPlane(photos=False), corners, repeatability(px=2))
    assert not floor.available and math.isnan(floor.value) and floor.reference == "none"
    assert floor.describe(0.1).startswith("field floor n/a:") and "stores no photos" in floor.describe(0.1)
    assert not floor.above(0.0), "an unknown floor must not claim eps is below it"


def test_an_exact_scene_has_no_field_floor():
    kind, reason = reference_kind(ground_truth("wall"))
    assert kind == "none" and "no field" in reason


def test_a_sut_whose_metric_is_undefined_everywhere_has_no_floor():
    def undefined(*_args):
        from pytest_n2r.errors import MetricUndefined

        raise MetricUndefined("nothing visible")

    metric = repeatability(px=2)
    metric.compute = undefined
    floor = measure_floor(BlurredPlane(blur=1.0, width=160, height=120), corners, metric)
    assert not floor.available and len(floor.samples) == 2
    assert "undefined on all 2 held-out views (nothing visible)" in floor.describe()


def test_the_store_reuses_a_floor_and_remeasures_an_edited_sut(tmp_path, measured):
    scene = BlurredPlane(blur=1.5, width=160, height=120)
    first = Counting(corners)
    a = measure_floor(scene, first, repeatability(px=2), store=FloorStore(tmp_path), name="corners")
    assert first.calls == 6, "photo, render and the nearest other photo brought there, for each of the 2 held-out views"
    assert measured[0] == 4, "the render's and the nearest photo's sample of each held-out view"
    again = Counting(corners)
    b = measure_floor(scene, again, repeatability(px=2), store=FloorStore(tmp_path), name="corners")
    assert again.calls == 6 and b == a, "the SUT runs on every image the floor is computed from, to name its outputs"
    assert measured[0] == 4, "a new store on the same folder reads the floor back: no metric is computed"
    assert len(list(tmp_path.glob("*.json"))) == 1

    edited = Counting(lambda rgb: corners(rgb)[::2])  # same name, other output: measured again
    c = measure_floor(scene, edited, repeatability(px=2), store=FloorStore(tmp_path), name="corners")
    assert edited.calls == 6 and c.key != a.key and measured[0] == 8
    other_size = measure_floor(scene, corners, repeatability(px=2), size=RenderSize.parse(80),
                               store=FloorStore(tmp_path), name="corners")
    assert other_size.key not in (a.key, c.key) and other_size.size == "80"


def test_an_edit_that_keeps_the_output_on_the_first_photo_is_measured_again(tmp_path):
    """Floors were keyed by the SUT's output on the first reference image alone: an edit that kept that one output
    reused the old SUT's floor (a real failure then warned "eps below the field floor" from a stale floor)."""
    scene = BlurredPlane(blur=1.5, width=160, height=120)
    first_photo = floor_views(scene)[0].image
    a = measure_floor(scene, corners, repeatability(px=2), store=FloorStore(tmp_path), name="corners")
    edited = Counting(lambda rgb: corners(rgb) if np.array_equal(rgb, first_photo) else corners(rgb)[::2])
    b = measure_floor(scene, edited, repeatability(px=2), store=FloorStore(tmp_path), name="corners")
    assert edited.calls == 6 and b.key != a.key, (
        f"the edited SUT's floor was taken from the store ({edited.calls} SUT calls): its output on the second "
        "photo differs")


def test_an_edit_that_changes_the_output_on_field_renders_alone_is_measured_again(tmp_path, measured):
    """Floors were keyed by the SUT's outputs on the reference images alone, though computed from its outputs on
    the field's renders too: an edited detector (an adaptive threshold, the same on sharp photos, other on the
    blurrier renders) got the old detector's floor back from a warm cache, and lost its "eps below the field floor"
    warning."""
    scene = BlurredPlane(blur=1.5, width=160, height=120)
    photos = [v.image for v in floor_views(scene)]
    a = measure_floor(scene, corners, repeatability(px=2), store=FloorStore(tmp_path), name="corners")

    def edited(rgb):  # the same output on every photo, its corners moved 4 pixels on anything else
        return corners(rgb) if any(np.array_equal(rgb, p) for p in photos) else corners(rgb) + 4.0

    before = measured[0]
    b = measure_floor(scene, edited, repeatability(px=2), store=FloorStore(tmp_path), name="corners")
    assert measured[0] > before and b.key != a.key, "the edited SUT's floor was taken from the store"
    assert b.value == measure_floor(scene, edited, repeatability(px=2)).value != a.value, (a.value, b.value)


def test_a_metric_whose_class_declares_no_result_version_is_never_kept(tmp_path, measured):
    """A user's metric is named by its ``repr`` alone, which an edit of its ``compute`` keeps: the edited metric's
    floor was the old one's (0.471 for 1.4 in the review's reproduction). As its kept results, its floor is kept
    only when its own class declares a ``result_version``."""

    class _Mine(Repeatability):  # a subclass of a kept metric that declares no version of its own
        pass

    class _Edited(Repeatability):
        def compute(self, out_source, out_follow, source, follow):
            result = super().compute(out_source, out_follow, source, follow)
            return self.result(result.score / 2)

    _Edited.__qualname__ = _Mine.__qualname__  # the same repr: an edit of _Mine.compute between two sessions
    scene = BlurredPlane(blur=1.5, width=160, height=120)
    a = measure_floor(scene, corners, _Mine(px=2), store=FloorStore(tmp_path), name="corners")
    assert measured[0] == 4 and not list(tmp_path.glob("*.json")), "an unversioned metric's floor was stored"
    b = measure_floor(scene, corners, _Edited(px=2), store=FloorStore(tmp_path), name="corners")
    assert repr(_Edited(px=2)) == repr(_Mine(px=2)) and measured[0] == 8, "the floor was taken from the store"
    assert b.value == pytest.approx((1 + a.value) / 2) and b.value != a.value, (a.value, b.value)


def test_a_metric_of_pytest_n2rs_own_is_kept_though_its_class_declares_no_result_version(tmp_path, measured):
    """Cosine, L2, class invariance and SSIM declare no ``result_version`` (their results are not kept); their code
    is pytest-n2r's, which the key names by its source digest, so their floors are kept as before."""
    from pytest_n2r.metrics import cosine_similarity

    def colour(rgb):
        return rgb.reshape(-1, 3).mean(axis=0)

    scene = BlurredPlane(blur=1.5, width=160, height=120)
    assert "result_version" not in vars(type(cosine_similarity()))
    a = measure_floor(scene, colour, cosine_similarity(), store=FloorStore(tmp_path), name="colour")
    assert measured[0] == 4 and list(tmp_path.glob("*.json")), "a built-in metric's floor was not stored"
    b = measure_floor(scene, colour, cosine_similarity(), store=FloorStore(tmp_path), name="colour")
    assert measured[0] == 4 and b.value == a.value, "a built-in metric's kept floor was measured again"


def test_a_floor_measured_by_other_code_is_measured_again(tmp_path, monkeypatch):
    """The key names the package's source, as a kept decision's does: an edited checkout (same version) measures
    again rather than reading a floor the old code measured."""
    scene = BlurredPlane(blur=1.5, width=160, height=120)
    a = measure_floor(scene, corners, repeatability(px=2), store=FloorStore(tmp_path), name="corners")
    monkeypatch.setattr("pytest_n2r.relation.floor.measure.source_digest", lambda: "edited checkout", raising=False)
    again = Counting(corners)
    b = measure_floor(scene, again, repeatability(px=2), store=FloorStore(tmp_path), name="corners")
    assert again.calls == 6 and b.key != a.key, f"a floor of other code was reused ({again.calls} SUT calls)"


def test_the_nearest_photo_brought_to_each_pose_says_what_the_capture_itself_gives():
    # The plane's photos are sharp and its poses differ by a sideways step (parallel optical axes): a photo
    # brought to the neighbouring pose keeps almost every corner, whatever the field's blur does to the render.
    sharp, soft = (measure_floor(BlurredPlane(blur=b, width=160, height=120), corners, repeatability(px=2))
                   for b in (0.0, 2.5))
    for floor in (sharp, soft):
        assert len(floor.nearby) == 2 and all(s.valid for s in floor.nearby), floor.nearby
        assert floor.nearby_degrees == 0.0 and floor.nearby_distance > 0, "the neighbour is not the view itself"
        assert floor.nearby_value < 0.15, f"a sharp photo moved by a sideways step lost {floor.nearby_value}"
    assert soft.value > 0.9 and sharp.value == 0.0, (soft.value, sharp.value)
    assert "; the nearest other photo brought to each pose (0.0° and 0.1 reference lengths away): 0.105" in (
        soft.describe()), soft.describe()
    assert FieldFloor.from_dict(soft.to_dict()) == soft


def test_the_floors_of_several_suts_bring_each_view_once(monkeypatch):
    from pytest_n2r.relation.floor import nearby

    calls = []
    original = nearby.brought_to_view
    monkeypatch.setattr(nearby, "brought_to_view", lambda *a: calls.append(1) or original(*a))
    monkeypatch.setattr(nearby, "_BROUGHT", type(nearby._BROUGHT)())
    scene = BlurredPlane(blur=1.5, width=160, height=120)
    first = measure_floor(scene, corners, repeatability(px=2))
    second = measure_floor(scene, lambda rgb: corners(rgb)[::2], repeatability(px=3))
    assert len(calls) == 2, f"2 held-out views brought {len(calls)} times for two floors"
    assert len(first.nearby) == len(second.nearby) == 2


def test_floor_round_trips_through_json():
    floor = measure_floor(BlurredPlane(blur=1.5, width=160, height=120), corners, repeatability(px=2))
    back = FieldFloor.from_dict(floor.to_dict())
    assert back == floor and floor.to_dict()["value"] == pytest.approx(floor.value)


def test_a_fitted_demo_scene_is_measured_against_its_exact_twin():
    scene = load_demo("wall-field", "cpu")
    assert reference_kind(scene) == ("exact", "")
    orb = resolve_sut("orb", None).fn
    # at 96 px ORB (31-px borders) finds no keypoint: that pair is undefined, not the ideal 1, so 160 px
    floor = measure_floor(scene, orb, repeatability(px=2), size=RenderSize.parse(160))
    assert floor.reference == "exact" and len(floor.samples) == len([v for v in scene.views
                                                                      if v.split == "heldout"])
    assert floor.available and 0.0 <= floor.value <= 1.0, floor
    assert floor.nearby == (), "on a fitted demo scene the exact replay says what the field does; no yardstick"
    with_nearby = measure_floor(scene, orb, repeatability(px=2), size=RenderSize.parse(160), nearby=True)
    assert len(with_nearby.nearby) == len(floor.samples) and with_nearby.value == floor.value
    assert "the nearest other view brought to each pose (" in with_nearby.describe(), with_nearby.describe()


def test_study_measures_a_fitted_demo_scene_against_its_exact_twin():
    """`n2r study demo:wall-field` gets RQ1 rows (it has no photos, but an exact twin)."""
    config = StudyConfig(examples=1, max_views=1, size=48, families=("m1",), fps_frames=1, fps_sizes=((48, 27),))
    result = run_study([load_demo("wall-field", "cpu")], [resolve_sut("orb", None)], config)
    assert {r["metric"] for r in result.domain_shift} == {"repeatability", "ip_spread"}
    assert {r["source"] for r in result.realness} == {"tau0", "m1", "m2", "m3"}
    assert all(r["psnr"] < math.inf for r in result.realness if r["source"] == "tau0")


def test_a_sut_cannot_draw_on_the_stored_photo():
    scene = BlurredPlane(blur=1.0, width=160, height=120)
    photo = scene.views[1].image.copy()

    def scribbler(rgb):
        rgb[:10] = 0  # raises: the floor hands the SUT a read-only image, like a cached render
        return corners(rgb)

    with pytest.raises(ValueError, match="read-only"):
        measure_floor(scene, scribbler, repeatability(px=2))
    assert np.array_equal(scene.views[1].image, photo), "the stored photo was changed"


class _OnKeypoints(Metric):
    """Repeatability of the keypoints a SUT returns first, beside other outputs (scores, ...)."""

    name, ideal, needs = "on_keypoints", 1.0, ("depth", "opacity")
    result_version = "1"  # a floor is kept only for a metric whose own class declares one

    def compute(self, out_source, out_follow, source, follow):
        return repeatability(px=2).compute(out_source[0], out_follow[0], source, follow)

    def __repr__(self):
        return "_OnKeypoints()"


class _Opaque:
    """An output part whose repr says nothing of its content."""

    def __init__(self, value):
        self.value = value

    def __repr__(self):
        return "_Opaque()"


def test_an_edit_deep_in_a_structured_output_is_measured_again(tmp_path):
    """A SUT returning keypoints and a dict of long arrays: an edit that changes one value far inside them once
    kept the floor's key (numpy's repr elides long arrays with '...'), so the stale floor was reused."""
    scene = BlurredPlane(blur=1.5, width=160, height=120)
    scores = np.arange(2000.0)
    first = Counting(lambda rgb: (corners(rgb), {"scores": scores}))
    a = measure_floor(scene, first, _OnKeypoints(), store=FloorStore(tmp_path), name="mine")
    edited_scores = scores.copy()
    edited_scores[1000] = -1.0
    edited = Counting(lambda rgb: (corners(rgb), {"scores": edited_scores}))
    b = measure_floor(scene, edited, _OnKeypoints(), store=FloorStore(tmp_path), name="mine")
    assert edited.calls == 6 and b.key != a.key, (
        f"the edited SUT's floor was taken from the store ({edited.calls} SUT calls): its output differs")


def test_an_output_no_digest_names_is_never_kept_or_reused(tmp_path):
    scene = BlurredPlane(blur=1.5, width=160, height=120)
    for value in (1, 2):  # the same repr, another output
        sut = Counting(lambda rgb, value=value: (corners(rgb), _Opaque(value)))
        floor = measure_floor(scene, sut, _OnKeypoints(), store=FloorStore(tmp_path), name="mine")
        assert sut.calls == 6 and floor.available, f"the floor of output {value} was not measured ({sut.calls} calls)"
    assert not list(tmp_path.glob("*.json")), "a floor keyed by an output no digest names exactly was stored"


def test_a_floor_of_keypoint_objects_beside_descriptors_is_kept_and_reused(tmp_path):
    """A ``(keypoints, descriptors)`` output as OpenCV's ``detectAndCompute`` returns it: the floor was measured
    every time, because its digest named a list of ``cv2.KeyPoint`` only at the top level of an output."""
    import cv2

    def detect(rgb):
        points = corners(rgb)
        return [cv2.KeyPoint(float(u), float(v), 7.0) for u, v in points], np.zeros((len(points), 32), np.uint8)

    class _OnKeypointObjects(_OnKeypoints):
        result_version = "1"

        def compute(self, out_source, out_follow, source, follow):
            as_points = [np.array([k.pt for k in out[0]], np.float32).reshape(-1, 2)
                         for out in (out_source, out_follow)]
            return repeatability(px=2).compute(*as_points, source, follow)

    scene = BlurredPlane(blur=1.5, width=160, height=120)
    first = Counting(detect)
    a = measure_floor(scene, first, _OnKeypointObjects(), store=FloorStore(tmp_path), name="mine")
    again = Counting(detect)
    b = measure_floor(scene, again, _OnKeypointObjects(), store=FloorStore(tmp_path), name="mine")
    assert a.available and len(list(tmp_path.glob("*.json"))) == 1, "the keypoint objects' floor was not stored"
    assert again.calls == 6 and b == a, f"the stored floor was not reused ({again.calls} SUT calls)"


def _floor(deviations: list[float]) -> FieldFloor:
    samples = tuple(ShiftSample(f"v{i}", 1 - d, d, True) for i, d in enumerate(deviations))
    return FieldFloor("s", "sut", "m", "view size", "photo", samples=samples)


def test_eps_below_the_floor_of_some_views_is_noted_though_above_the_mean():
    """The warning compares eps with the mean floor, but a relation fails on its worst example: floors of
    0.1, 0.1, 0.1 and 0.9 with eps 0.5 said nothing."""
    text = _floor([0.1, 0.1, 0.1, 0.9]).describe(0.5)
    assert "WARNING" not in text and "note: eps 0.5 is below the floor on 1 of 4 held-out views (max 0.9)" in text
    assert "note" not in _floor([0.1, 0.2]).describe(0.5)


def test_a_metric_returning_a_nan_deviation_is_no_floor_sample():
    """One NaN sample made the floor NaN and silently turned its warning off."""
    from pytest_n2r.metrics.base import MetricResult
    from pytest_n2r.relation.floor.reference import shift_sample

    class _Broken(Metric):
        name, ideal = "broken", 1.0

        def compute(self, a, b, source=None, follow=None):
            return MetricResult(self.name, math.nan, math.nan, {})

    sample = shift_sample(_Broken(), 1, 2, None, None, "v0")
    assert not sample.valid and "returned a valid result with deviation nan" in sample.reason, sample


@pytest.mark.parametrize("content", ["[" * 100000 + "]" * 100000, '"a floor"', '{"scene": 1, "samples": [[1]]}',
                                     "{torn"])
def test_a_stored_floor_that_cannot_be_read_is_measured_again(tmp_path, content):
    (tmp_path / "k.json").write_text(content)
    assert FloorStore(tmp_path).get("k") is None
