"""Demo scenes as captures, exported transforms.json, the CLI, and interest points for real SUTs."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from pytest_n2r.cli.main import main
from pytest_n2r.demo import capture, demo_scene_names, export, ground_truth
from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.geometry import opengl_to_opencv, project


def test_capture_has_images_poses_points_and_bounds():
    scene = ground_truth("object")
    cap = capture("object", size=64)
    assert len(cap.views) == len(scene.views)
    assert len(cap.heldout_views) == 6 and len(cap.train_views) == 42
    v = cap.views[5]
    assert v.image.shape == (36, 64, 3) and v.image.dtype == np.uint8
    assert v.camera.width == 64 and np.array_equal(v.c2w, scene.views[5].c2w)
    assert cap.reference_length == scene.reference_length
    lo, hi = cap.bounds
    assert cap.points.shape[1] == 3 and len(cap.points) > 1000
    inside = np.all((cap.points >= lo) & (cap.points <= hi), axis=1)
    assert inside.mean() > 0.95, f"only {inside.mean():.1%} of the points are inside the bounds"
    # the points are on surfaces the training cameras see: each projects in front of some camera
    _, z = project(cap.points[:50], v.camera, v.c2w)
    assert np.isfinite(z).all()


@pytest.mark.parametrize("size", [0, (4, 4), "big", True, (64,)])
def test_capture_size_is_checked(size):
    with pytest.raises((InvalidArgument, InvalidType), match="size="):
        capture("wall", size=size)


def test_export_writes_a_nerfstudio_transforms_json(tmp_path):
    scene = ground_truth("wall")
    path = export("wall", tmp_path, size=(48, 27))
    meta = json.loads(path.read_text())
    assert meta["camera_model"] == "OPENCV" and (meta["w"], meta["h"]) == (48, 27)
    cam = scene.views[0].camera.resized(48, 27)
    assert meta["cx"] == pytest.approx(cam.cx + 0.5) and meta["fl_x"] == pytest.approx(cam.fx)
    assert len(meta["frames"]) == len(scene.views)
    assert set(meta["val_filenames"]) == {f"images/{v.name}" for v in scene.views if v.split == "heldout"}
    for frame, view in zip(meta["frames"], scene.views):
        c2w = opengl_to_opencv(np.array(frame["transform_matrix"]))
        np.testing.assert_allclose(c2w, view.c2w, atol=1e-12)
        image = cv2.cvtColor(cv2.imread(str(tmp_path / frame["file_path"])), cv2.COLOR_BGR2RGB)
        assert image.shape == (27, 48, 3)
    first = scene.render(scene.views[0].c2w, cam, "rgb").rgb
    on_disk = cv2.cvtColor(cv2.imread(str(tmp_path / meta["frames"][0]["file_path"])), cv2.COLOR_BGR2RGB)
    assert np.array_equal(on_disk, first), "exported image is not the ground truth in RGB order"
    assert not [p for p in tmp_path.rglob(".*")], "temporary files were left behind"


def test_export_round_trips_through_ingestion(tmp_path):
    """`n2r demo export` output is an ordinary capture: ingestion reads back the same images and poses."""
    from pytest_n2r.data import ingest

    scene = ground_truth("object")
    ours = capture("object", size=(64, 36))
    export("object", tmp_path, size=(64, 36))
    cap = ingest(tmp_path / "transforms.json")
    assert [v.name for v in cap.views] == [f"images/{v.name}" for v in ours.views]
    assert [v.split for v in cap.views] == [v.split for v in ours.views]
    for got, want in zip(cap.views, ours.views):
        np.testing.assert_allclose(got.c2w, want.c2w, atol=1e-9)
        assert got.camera.cx == pytest.approx(want.camera.cx) and got.camera.fy == pytest.approx(want.camera.fy)
        assert np.array_equal(got.image, want.image), f"{got.name}: pixels changed on the way through the files"
    # ingestion triangulates its own points from the images; their median depth is close to the exact one
    assert cap.reference_length == pytest.approx(scene.reference_length, rel=0.25)


def test_cli_lists_and_exports(tmp_path, capsys):
    assert main(["demo", "list"]) == 0
    listed = capsys.readouterr().out
    for name in demo_scene_names():
        assert name in listed
    assert main(["demo", "export", "object", "-o", str(tmp_path / "out"), "--size", "32x18"]) == 0
    assert (tmp_path / "out" / "transforms.json").is_file()
    assert len(list((tmp_path / "out" / "images").glob("*.png"))) == 48
    assert main(["demo", "export", "nope", "-o", str(tmp_path)]) == 2
    assert "'nope'" in capsys.readouterr().err


@pytest.mark.parametrize("name", demo_scene_names())
def test_orb_finds_interest_points_on_every_heldout_view(name):
    """Real interest-point detectors have something to find: >= 250 ORB points (of 500) per 480x270 view."""
    scene = ground_truth(name)
    counts = {}
    for v in scene.views:
        if v.split != "heldout":
            continue
        gray = cv2.cvtColor(scene.render(v.c2w, v.camera, "rgb").rgb, cv2.COLOR_RGB2GRAY)
        counts[v.name] = len(cv2.ORB_create(500).detect(gray))
    assert min(counts.values()) >= 250, f"{name}: too few ORB points per view: {counts}"
