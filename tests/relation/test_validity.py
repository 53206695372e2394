"""When a rendered follow-up view is a fair input: empty views and views outside the captured region."""

from __future__ import annotations

import pytest

from pytest_n2r import InvalidArgument, InvalidType, Transform
from pytest_n2r.relation import Relation, RunSettings, Validity, check_relation
from pytest_n2r.strategies import transforms
from tests.plugin.fakemetrics import AbsDifference
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


def test_a_subclass_checks_every_run_where_the_built_in_checks_are_taken_from_the_cache(tmp_path, monkeypatch):
    """A user's Validity subclass is code no key names: edited to reject dark views, it was handed the old code's
    "valid" from a warm render cache (a CI runner restoring the cache passed what a fresh one fails)."""
    from pytest_n2r.scene.render_cache import RenderCache

    calls = []
    check = Validity.check
    monkeypatch.setattr(Validity, "check", lambda self, *args: calls.append(1) or check(self, *args))

    class Users(Validity):
        """A subclass whose checks the user edits between runs."""

    settings = RunSettings(examples=5, database=None, derandomize=True)
    for validity, kept in ((Users(), False), (Validity(), True)):
        relation = Relation.build(AbsDifference(), 255.0, transforms(yaw=(0, 5)), validity=validity)
        checked = []
        for _ in range(2):  # a cold run, then a run on the filled cache
            calls.clear()
            check_relation(PlaneScene(), lambda rgb: float(rgb.mean()), relation, settings=settings,
                           cache=RenderCache(tmp_path / type(validity).__name__))
            checked.append(len(calls))
        assert checked[0] > 0 and (checked[1] == 0) == kept, f"{type(validity).__name__}: checks cold, warm {checked}"
    assert Users().verdict_key(PlaneScene(), "1" * 64, "2" * 64) is None


def test_a_relation_whose_every_draw_is_rejected_fails_even_when_max_rejected_allows_all():
    # yaw 80-89 degrees turns every follow-up away from the plane: every draw is an empty view
    relation = Relation.build(AbsDifference(), 0.0, transforms(yaw=(80, 89)), validity=Validity(max_rejected=1.0))
    with pytest.raises(InvalidArgument, match="no follow-up view was valid, so nothing was compared") as caught:
        check_relation(PlaneScene(), lambda rgb: float(rgb.mean()), relation,
                       settings=RunSettings(examples=5, database=None))
    assert "in 100% of" in str(caught.value), f"the message should give the share of rejected draws: {caught.value}"


def test_max_rejected_one_still_passes_a_relation_with_some_valid_examples():
    # yaw up to 40 degrees: some follow-ups leave the plane, the small ones stay on it
    relation = Relation.build(AbsDifference(), 255.0, transforms(yaw=(0, 40)), validity=Validity(max_rejected=1.0))
    record = check_relation(PlaneScene(), lambda rgb: float(rgb.mean()), relation,
                            settings=RunSettings(examples=10, database=None, derandomize=True))
    assert record.outcome == "passed" and record.valid_examples, (
        f"a relation with valid examples should pass under max_rejected=1: {record.summary_line()}")


@pytest.mark.parametrize("grid", [2.5, 16.0, "16", True])
def test_the_grid_must_be_an_int(grid):
    with pytest.raises((InvalidArgument, InvalidType), match=r"grid=.* must be an int"):
        Validity(grid=grid)


def test_the_grid_must_be_in_range():
    with pytest.raises(InvalidArgument, match=r"grid=1 is out of range; expected an int in \[2, 256\]"):
        Validity(grid=1)


def test_max_rejected_zero_passes_a_relation_with_no_invalid_draw():
    """``max_rejected=0`` allows no invalid draw, so a run with none passes: compared with ``>=`` the share 0 was
    "too many" and the strictest setting failed every relation, however valid its draws."""
    relation = Relation.build(AbsDifference(), 255.0, transforms(yaw=(0.5, 2)), validity=Validity(max_rejected=0.0))
    record = check_relation(PlaneScene(), lambda rgb: float(rgb.mean()), relation,
                            settings=RunSettings(examples=8, database=None, derandomize=True))
    assert record.rejected == 0, f"the test needs a run without invalid draws: {record.summary_line()}"
    assert record.outcome == "passed" and len(record.valid_examples) == 8, (
        f"max_rejected=0 with no invalid draw should pass: {record.summary_line()}")


def test_a_view_with_no_solid_pixel_has_no_coverage_and_is_not_valid():
    """A follow-up that shows nothing (every pixel empty) has no surface a training camera saw: its coverage is 0.
    Were it 1, turning the empty-view check off (``max_empty_increase=1``) let blank views through as valid."""
    scene = PlaneScene()
    view = scene.views[1]
    blank = scene.render(Transform(yaw=85).apply(view.c2w), view.camera, ("rgb", "depth", "opacity"))
    assert not (blank.opacity >= 0.5).any(), "the test needs a follow-up without a solid pixel"
    coverage = Validity().coverage(blank, scene)
    assert coverage == 0.0, f"a view with no solid pixel has coverage {coverage}, expected 0"
    verdict = Validity(max_empty_increase=1.0).check(blank, scene)
    assert (verdict.valid, verdict.reason) == (False, "outside the captured region"), (
        f"a blank view passed the coverage check: {verdict}")


@pytest.mark.parametrize("limit", [0.5, 0.8])
def test_the_search_never_gives_up_on_invalid_draws_before_40_of_them(limit):
    """Giving up needs at least 40 invalid draws, whatever ``max_rejected``: with a lower floor (20) a relation with a
    ``max_rejected`` under 0.9 was given up on after a short unlucky start, though the bound alone says so."""
    from pytest_n2r.relation.validity import too_many_invalid_so_far

    assert not too_many_invalid_so_far(39, 39, limit), f"gave up after 39 invalid draws of 39 (max_rejected {limit})"
    assert too_many_invalid_so_far(40, 40, limit), f"40 invalid draws of 40 should end it (max_rejected {limit})"


def test_a_verdict_key_names_the_source_render():
    """Guards against a verdict key without the source render's key: the verdict on one follow-up of another
    source view (its empty-pixel increase is relative to the source) was reused."""
    scene, follow = PlaneScene(), "2" * 64
    assert Validity().verdict_key(scene, "1" * 64, follow) != Validity().verdict_key(scene, "3" * 64, follow), (
        "another source render, same verdict key")


def test_the_coverage_of_a_view_rendered_without_depth_names_what_it_lacks():
    """``coverage`` reads the view's depth and opacity: on a view rendered without them it failed with
    ``'NoneType' object is not subscriptable`` instead of naming the outputs it needs."""
    scene = PlaneScene()
    view = scene.views[1]
    with pytest.raises(InvalidArgument, match=r"rendered without depth; expected a view rendered with outputs"):
        Validity().coverage(scene.render(view.c2w, view.camera, ("rgb", "opacity")), scene)
