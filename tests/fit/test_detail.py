"""How much detail a capture gives a field: pixel footprints, the matching grid, the finer grid added."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pytest_n2r.data.capture import Capture, CapturedView
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.fit.budget import LONG_BUDGET_S, budget_config
from pytest_n2r.fit.detail import (
    DETAIL_GRID_MULTIPLE,
    DETAIL_STAGE_AT,
    CaptureDetail,
    capture_detail,
    detailed_config,
)
from pytest_n2r.geometry import Camera

CAMERA = Camera(200, 100, 100.0, 100.0, 99.5, 49.5)


def _view(name: str, z: float) -> CapturedView:
    """A camera at (0, 0, -z) looking along +z at the plane z = 0."""
    c2w = np.eye(4)
    c2w[2, 3] = -z
    return CapturedView(name, CAMERA, c2w)


def _capture(depths: list[float], points: np.ndarray | None = None) -> Capture:
    if points is None:  # a grid of points on the plane z = 0, in view of every camera
        xs, ys = np.meshgrid(np.linspace(-0.5, 0.5, 8), np.linspace(-0.2, 0.2, 4))
        points = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    views = [_view(f"v{k}", z) for k, z in enumerate(depths)]
    return Capture(views, points, np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]]), 1.0)


def test_the_footprint_is_depth_over_focal_length_in_normalized_units():
    space = SceneSpace((0.0, 0.0, 0.0), 2.0)
    detail = capture_detail(_capture([1.0, 2.0, 4.0]), space)
    assert detail.views == 3
    assert detail.median == pytest.approx(2.0 / 100.0 / 2.0)
    assert detail.close == pytest.approx(np.percentile([1 / 200, 2 / 200, 4 / 200], 10))
    # a voxel of the matching grid is no larger than the close footprint, one vertex fewer and it would be
    res = detail.matching_resolution()
    assert space.voxel_size(res) <= detail.close < space.voxel_size(res - 1)
    assert detail.pixels_per_voxel(res) <= 1.0 < detail.pixels_per_voxel(res - 1)
    assert detail.describe(160)["pixels_per_voxel"] == round(detail.pixels_per_voxel(160), 2)


def test_views_that_see_too_few_points_do_not_count_and_none_means_nothing_to_measure():
    space = SceneSpace((0.0, 0.0, 0.0), 2.0)
    behind = _capture([1.0], points=np.array([[0.0, 0.0, -5.0]] * 20))  # every point behind the camera
    assert capture_detail(behind, space) is None
    assert capture_detail(_capture([1.0], points=np.zeros((0, 3))), space) is None
    few = _capture([1.0], points=np.zeros((5, 3)))
    assert capture_detail(few, space) is None


def test_a_fit_reports_how_many_training_pixels_its_finest_voxel_spans(short_fit, capture48, tmp_path):
    from pytest_n2r.cli.info import format_info
    from pytest_n2r.scene.file import read_scene_file, save_scene

    detail = short_fit.report["detail"]
    expected = capture_detail(capture48, short_fit.field.space)
    assert detail == {**expected.describe(short_fit.field.resolution), "grid_added": None}
    assert expected.matching_resolution() > short_fit.field.resolution
    assert detail["pixels_per_voxel"] == pytest.approx(expected.pixels_per_voxel(short_fit.field.resolution), abs=0.01)
    path = save_scene(tmp_path / "s.n2r", short_fit.field, short_fit.config, capture48, short_fit.report,
                      images=False)
    text = format_info(read_scene_file(path, images=False))
    assert (f"a voxel spans {detail['pixels_per_voxel']:.1f} training pixels where the cameras look closest "
            f"(a {detail['matching_resolution']}³ grid would match the photos)") in text, text


# -- the finer grid a fit adds where its ladder is too coarse for the photos ------------------------------------


def _detail_at(pixels_per_voxel: float, resolution: int = 224) -> CaptureDetail:
    """A capture whose close footprint makes a voxel of ``resolution``³ span ``pixels_per_voxel`` pixels."""
    space = SceneSpace((0.0, 0.0, 0.0), 1.0)
    close = space.voxel_size(resolution) / pixels_per_voxel
    return CaptureDetail(close, close, 10, space)


def test_a_ladder_fine_enough_for_the_photos_or_given_is_kept_as_it_is():
    config = FieldConfig()
    assert detailed_config(config, _detail_at(5.1)) is config  # the fox's 10-minute fit
    assert detailed_config(config, None) is config  # nothing measured: nothing to follow
    assert detailed_config(config.replace(max_pixels_per_voxel=0.0), _detail_at(20.0)).resolutions == (32, 96, 224)
    given_ladder = FieldConfig(resolutions=(16, 24), stage_fractions=(0.5,))
    assert detailed_config(given_ladder, _detail_at(20.0, 24)) is given_ladder


def test_the_default_ladder_gets_one_finer_grid_for_the_last_part_of_the_run_where_the_photos_are_finer():
    detailed = detailed_config(FieldConfig(), _detail_at(9.0))  # the wall's phone capture at 480×270
    assert detailed.resolutions == (32, 96, 224, 384), detailed.resolutions
    assert detailed.stage_fractions == (0.1, 0.35, DETAIL_STAGE_AT), detailed.stage_fractions
    # the grid is the coarsest multiple of 64 that meets the limit: 6.5 pixels need 243 vertices, so 256
    assert detailed_config(FieldConfig(), _detail_at(6.5)).resolutions[-1] == 256


def test_a_long_budgets_ladder_gets_the_finer_grid_too_where_its_256_grid_is_coarser_than_the_photos():
    long = budget_config(FieldConfig(), LONG_BUDGET_S)
    assert long.resolutions[-1] == 256, long.resolutions
    detailed = detailed_config(long, _detail_at(9.0))  # the wall's phone capture: 7.9 pixels a voxel at 256³
    assert detailed.resolutions == (32, 96, 256, 384), detailed.resolutions
    assert detailed.stage_fractions == (0.1, 0.35, DETAIL_STAGE_AT), detailed.stage_fractions
    assert detailed_config(long, _detail_at(6.5)) is long, "256³ meets 6 pixels a voxel where 224³ spans 6.5"


@given(pixels=st.floats(0.5, 60.0), limit=st.floats(1.0, 12.0), cap=st.integers(8, 1024))
def test_a_finer_grid_is_added_exactly_where_the_limit_is_missed_and_meets_it_unless_capped(pixels, limit, cap):
    config = FieldConfig(max_pixels_per_voxel=limit, detail_grid_max=cap)
    detail = _detail_at(pixels)
    detailed = detailed_config(config, detail)
    if detail.pixels_per_voxel(224) <= limit or cap <= 224:
        assert detailed is config, f"{detailed.resolutions} for {pixels:.2f} pixels a voxel (limit {limit:.2f})"
        return
    *kept, added = detailed.resolutions
    assert tuple(kept) == config.resolutions and detailed.stage_fractions == (0.1, 0.35, DETAIL_STAGE_AT)
    assert 224 < added <= cap, f"{added}³ for a cap of {cap}"
    if added < cap:  # not capped: the coarsest multiple of 64 that meets the limit
        assert added % DETAIL_GRID_MULTIPLE == 0, added
        assert detail.pixels_per_voxel(added) <= limit, f"{added}³ spans {detail.pixels_per_voxel(added):.2f}"
        coarser = added - DETAIL_GRID_MULTIPLE
        assert coarser <= 224 or detail.pixels_per_voxel(coarser) > limit, f"{coarser}³ would have met it"


def test_a_fit_trains_the_added_grid_and_its_scene_file_says_so(capture48, tmp_path, monkeypatch):
    from pytest_n2r.cli.info import format_info
    from pytest_n2r.fit import detail as detail_module
    from pytest_n2r.fit import fit
    from pytest_n2r.scene.file import read_scene_file, save_scene

    from .conftest import SHORT_CONFIG

    # the default ladder's grids take minutes to fit; the short one stands in for it (a voxel of 24³ spans 4.6 of
    # this 48×27 capture's pixels, so a limit of 3 asks for 36 vertices: 64, capped at 32)
    monkeypatch.setattr(detail_module, "LIBRARY_LADDERS", ((SHORT_CONFIG.resolutions, SHORT_CONFIG.stage_fractions),))
    config = SHORT_CONFIG.replace(max_pixels_per_voxel=3.0, detail_grid_max=32)
    result = fit(capture48, config, max_steps=20, device="cpu")
    assert result.config.resolutions == (16, 24, 32), result.config.resolutions
    assert result.config.stage_fractions == (0.5, DETAIL_STAGE_AT)
    assert result.field.resolution == 32 and "32" in result.report["step_ms"], result.report["step_ms"].keys()
    assert result.report["detail"]["grid_added"] == 32
    assert result.report["detail"]["pixels_per_voxel"] == pytest.approx(4.6 * 23 / 31, abs=0.05)
    path = save_scene(tmp_path / "s.n2r", result.field, result.config, capture48, result.report, images=False)
    scene = read_scene_file(path, images=False)
    assert scene.config.resolutions == (16, 24, 32)
    assert "32³ added for the end of the fit: the ladder's grids were coarser than the photos" in format_info(scene)


def test_the_detail_settings_are_checked():
    with pytest.raises(InvalidArgument, match=r"detail_grid_max=2000: expected a grid size in 8\.\.1024"):
        FieldConfig(detail_grid_max=2000)
    with pytest.raises(InvalidArgument, match=r"max_pixels_per_voxel=-1\.0: expected a finite number >= 0"):
        FieldConfig(max_pixels_per_voxel=-1.0)


def test_only_the_training_views_set_the_footprint():
    """A held-out photo taken closer than every fitted one must not ask for a finer grid: the split leaks otherwise."""
    import dataclasses

    space = SceneSpace((0.0, 0.0, 0.0), 2.0)
    capture = _capture([4.0, 4.0, 4.0])
    closer = dataclasses.replace(_view("held", 0.5), split="heldout")  # sees all 32 points, 8× closer
    detail = capture_detail(dataclasses.replace(capture, views=[*capture.views, closer]), space)
    assert (detail.views, detail.close) == (3, pytest.approx(4.0 / 100.0 / 2.0)), (
        f"{detail.views} views with a close footprint of {detail.close}: the held-out view was measured")
