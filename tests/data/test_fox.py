"""The real fox capture (research data beside the checkout; skipped when absent)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from pytest_n2r.data import ingest, read_transforms_json
from pytest_n2r.data.colmap import read_colmap_model, write_colmap_text
from pytest_n2r.geometry import project

from ..conftest import shared_scene


@pytest.fixture(scope="module")
def fox():
    return shared_scene("fox")


def test_fox_transforms_json_loads_50_of_67_frames(fox):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        poses = read_transforms_json(fox / "transforms.json")
    missing = [str(w.message) for w in caught if "does not exist" in str(w.message)]
    assert len(poses.frames) == 50 and len(missing) == 17 and len(poses.skipped) == 17
    assert "images/0005.jpg" in missing[0]
    cam = poses.frames[0].camera
    assert (cam.width, cam.height) == (1080, 1920) and cam.cx == pytest.approx(554.558 - 0.5)


@pytest.mark.slow
def test_fox_ingest_quarter_size_cameras_look_at_the_scene(fox):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cap = ingest(fox / "transforms.json", downscale=0.25)
    assert len(cap.views) == 50 and len(cap.heldout_views) == 7
    assert cap.views[0].image.shape == (480, 270, 3)
    assert len(cap.points) > 1000
    for view in cap.views:
        _, z = project(cap.points, view.camera, view.c2w)
        assert np.mean(z > 0) > 0.99, f"{view.name}: triangulated points behind the camera"
    lo, hi = cap.bounds
    assert np.all(lo < hi) and 0 < cap.reference_length < np.linalg.norm(hi - lo)


def test_fox_transforms_json_and_colmap_model_load_to_the_same_cameras(fox, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        poses = read_transforms_json(fox / "transforms.json")
    write_colmap_text(tmp_path / "sparse" / "0", poses)
    model = read_colmap_model(tmp_path / "sparse" / "0", images_dir=fox)
    assert [f.name for f in model.frames] == sorted(f.name for f in poses.frames)
    by_name = {f.name: f for f in poses.frames}
    for frame in model.frames:
        ref = by_name[frame.name]
        assert frame.camera == ref.camera and frame.path == ref.path
        np.testing.assert_allclose(frame.c2w, ref.c2w, atol=1e-12)
