"""How much detail a capture gives a field: pixel footprints, the matching grid, the memory ceiling."""

from __future__ import annotations

import numpy as np
import pytest

from pytest_n2r.data.capture import Capture, CapturedView
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.field.space import SceneSpace
from pytest_n2r.fit.detail import capture_detail, fit_memory_bytes, memory_resolution
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


def test_the_memory_ceiling_grows_with_memory_and_the_estimate_with_the_grid():
    sizes = [memory_resolution(gib * 2**30) for gib in (1, 4, 24)]
    assert sizes == sorted(sizes) and sizes[0] < sizes[-1]
    for r in sizes:
        assert fit_memory_bytes(r) <= max(gib * 2**30 for gib in (1, 4, 24))
    assert fit_memory_bytes(385) > fit_memory_bytes(384)
    assert fit_memory_bytes(384, occupied=0.2) > fit_memory_bytes(384, occupied=0.1)


@pytest.mark.parametrize("call, message", [
    (lambda: memory_resolution(0), "memory_bytes=0"),
    (lambda: memory_resolution(1000), "not even a 16³ grid"),
    (lambda: fit_memory_bytes(1), "resolution=1"),
    (lambda: fit_memory_bytes(64, occupied=0.0), "occupied=0.0"),
])
def test_bad_arguments_are_named(call, message):
    with pytest.raises(InvalidArgument, match=message):
        call()


def test_a_fit_reports_how_many_training_pixels_its_finest_voxel_spans(short_fit, capture48, tmp_path):
    from pytest_n2r.cli.info import format_info
    from pytest_n2r.scene.file import read_scene_file, save_scene

    detail = short_fit.report["detail"]
    expected = capture_detail(capture48, short_fit.field.space)
    assert detail == expected.describe(short_fit.field.resolution)
    assert expected.matching_resolution() > short_fit.field.resolution
    assert detail["pixels_per_voxel"] == pytest.approx(expected.pixels_per_voxel(short_fit.field.resolution), abs=0.01)
    path = save_scene(tmp_path / "s.n2r", short_fit.field, short_fit.config, capture48, short_fit.report,
                      images=False)
    text = format_info(read_scene_file(path, images=False))
    assert (f"a voxel spans {detail['pixels_per_voxel']:.1f} training pixels where the cameras look closest "
            f"(a {detail['matching_resolution']}³ grid would match the photos)") in text, text
