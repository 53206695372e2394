"""COLMAP sparse models (text written by hand, and binary via pycolmap) into our cameras and poses."""

from __future__ import annotations

import numpy as np
import pytest

from pytest_n2r.data.colmap import camera_from_colmap, find_colmap_model, read_colmap_model, write_colmap_text
from pytest_n2r.data.transforms_json import read_transforms_json
from pytest_n2r.errors import IngestError
from pytest_n2r.geometry import rotation_from_euler

from .synthetic import write_transforms

# Two images: one at the origin looking down +z, one 1 unit along world +x turned by yaw 90 degrees.
# COLMAP stores world-to-camera: for c2w = [R | c], qvec is R^T as a quaternion and tvec = -R^T c.
_CAMERAS = "# hand-written\n1 SIMPLE_RADIAL 640 480 500 320 240 0.01\n2 PINHOLE 320 240 250 260 160 120\n"
_S = np.sqrt(0.5)
_IMAGES = (
    "# IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME\n"
    "1 1 0 0 0 0 0 0 1 a.jpg\n\n"
    f"2 {_S} 0 {-_S} 0 0 0 1 2 b.jpg\n"
    "10 20 1 30 40 2\n"
)
_POINTS = "1 0 0 5 255 0 0 0.5 2 0\n2 1 0 4 0 255 0 0.5 2 1\n"


@pytest.fixture
def model(tmp_path):
    folder = tmp_path / "project" / "sparse" / "0"
    folder.mkdir(parents=True)
    (folder / "cameras.txt").write_text(_CAMERAS)
    (folder / "images.txt").write_text(_IMAGES)
    (folder / "points3D.txt").write_text(_POINTS)
    images = tmp_path / "project" / "images"
    images.mkdir()
    for name in ("a.jpg", "b.jpg", "c.jpg"):
        (images / name).write_bytes(b"")
    return tmp_path / "project"


def test_text_model_cameras_poses_points(model):
    poses = read_colmap_model(model / "sparse" / "0")
    a, b = poses.frames
    assert (a.name, b.name) == ("a.jpg", "b.jpg")
    assert (a.camera.fx, a.camera.fy, a.camera.cx, a.camera.cy) == (500.0, 500.0, 319.5, 239.5)
    assert a.camera.distortion == (0.01, 0.0, 0.0, 0.0)
    assert (b.camera.fx, b.camera.fy, b.camera.cx, b.camera.cy, b.camera.distortion) == (250, 260, 159.5, 119.5, ())
    np.testing.assert_allclose(a.c2w, np.eye(4), atol=1e-12)
    # qvec (w, x, y, z) = (cos 45, 0, -sin 45, 0) is R^T = R_y(-90): the camera is R_y(+90) (yaw 90),
    # and tvec = -R^T c = (0, 0, 1) puts its centre at c = R (0, 0, -1) = (-1, 0, 0).
    np.testing.assert_allclose(b.c2w[:3, :3], rotation_from_euler(0, 0, 90), atol=1e-7)
    np.testing.assert_allclose(b.c2w[:3, 3], [-1.0, 0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(poses.points, [[0, 0, 5], [1, 0, 4]])
    assert a.path == model / "images" / "a.jpg"
    assert poses.skipped == [("c.jpg", "not registered in the COLMAP model")]


def test_binary_model_reads_the_same(model, tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    binary = tmp_path / "bin"
    binary.mkdir()
    pycolmap.Reconstruction(str(model / "sparse" / "0")).write_binary(str(binary))
    assert (binary / "cameras.bin").is_file() and not (binary / "cameras.txt").exists()
    text, binp = read_colmap_model(model / "sparse" / "0"), read_colmap_model(binary, images_dir=model / "images")
    for f, g in zip(text.frames, binp.frames):
        assert f.name == g.name and f.camera == g.camera
        np.testing.assert_allclose(f.c2w, g.c2w, atol=1e-12)


def test_model_folder_is_found_from_the_project(model):
    assert find_colmap_model(model) == model / "sparse" / "0"
    assert find_colmap_model(model / "images") is None


@pytest.mark.parametrize(
    ("name", "params", "expected"),
    [
        ("SIMPLE_PINHOLE", [100, 50, 40], (100, 100, 49.5, 39.5, ())),
        ("PINHOLE", [100, 110, 50, 40], (100, 110, 49.5, 39.5, ())),
        ("SIMPLE_RADIAL", [100, 50, 40, 0.1], (100, 100, 49.5, 39.5, (0.1, 0.0, 0.0, 0.0))),
        ("RADIAL", [100, 50, 40, 0.1, -0.2], (100, 100, 49.5, 39.5, (0.1, -0.2, 0.0, 0.0))),
        ("OPENCV", [100, 110, 50, 40, 0.1, -0.2, 0.01, 0.02], (100, 110, 49.5, 39.5, (0.1, -0.2, 0.01, 0.02))),
        ("FULL_OPENCV", [100, 110, 50, 40, 0.1, -0.2, 0.01, 0.02, 0.3, 0.4, 0.5, 0.6],
         (100, 110, 49.5, 39.5, (0.1, -0.2, 0.01, 0.02, 0.3, 0.4, 0.5, 0.6))),
    ],
)
def test_camera_models(name, params, expected):
    cam = camera_from_colmap(name, 100, 80, params)
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.distortion) == expected


def test_unsupported_model_and_wrong_param_count():
    with pytest.raises(IngestError, match="'OPENCV_FISHEYE' is not supported"):
        camera_from_colmap("OPENCV_FISHEYE", 100, 80, [1, 1, 1, 1, 0, 0, 0, 0], where="cam 3")
    with pytest.raises(IngestError, match="PINHOLE has 3 parameters; expected 4"):
        camera_from_colmap("PINHOLE", 100, 80, [1, 2, 3])


def test_not_a_model_folder(tmp_path):
    with pytest.raises(IngestError, match="is not a COLMAP model folder"):
        read_colmap_model(tmp_path)


def test_corrupt_model_names_the_folder(tmp_path):
    (tmp_path / "cameras.txt").write_text("1 PINHOLE 64 48\n")
    (tmp_path / "images.txt").write_text("")
    with pytest.raises(IngestError, match=str(tmp_path)):
        read_colmap_model(tmp_path)


def test_write_colmap_text_round_trips_transforms_json(corner, tmp_path):
    poses = read_transforms_json(write_transforms(corner))
    poses.points = np.array([[0.1, 0.2, 0.3]])
    write_colmap_text(tmp_path / "sparse", poses)
    again = read_colmap_model(tmp_path / "sparse", images_dir=corner.root)
    assert [f.name for f in again.frames] == [f.name for f in poses.frames]
    for f, g in zip(poses.frames, again.frames):
        assert f.camera == g.camera and g.path == f.path
        np.testing.assert_allclose(f.c2w, g.c2w, atol=1e-12)
    np.testing.assert_allclose(again.points, poses.points)
