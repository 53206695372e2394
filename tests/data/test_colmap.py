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


def test_frames_and_rigs_beyond_their_files_are_refused_before_pycolmap_loops(model, tmp_path):
    """COLMAP 3.12's frames.bin and rigs.bin (pycolmap 4.2 writes and reads them): a frames.bin claiming 10^12 frames
    and holding none made pycolmap loop on failed reads without end (killed after 30 s)."""
    import shutil
    import struct

    pycolmap = pytest.importorskip("pycolmap")
    binary = tmp_path / "bin"
    binary.mkdir()
    pycolmap.Reconstruction(str(model / "sparse" / "0")).write_binary(str(binary))
    if not (binary / "frames.bin").is_file():
        pytest.skip("this pycolmap writes no frames.bin")
    frames = (binary / "frames.bin").read_bytes()
    cases = {"frames.bin": (struct.pack("<Q", 10**12), "the header claims 1000000000000 records"),
             "rigs.bin": (struct.pack("<Q", 10**12), "the header claims 1000000000000 records")}
    cases["frames.bin "] = (frames[:72] + struct.pack("<I", 5000) + frames[76:],
                            "frame record 1 of 2 (at byte 8) claims 5000 data ids (16 bytes each)")
    for name, (content, expected) in cases.items():
        damaged = tmp_path / f"damaged-{len(content)}-{name.strip()}"
        shutil.copytree(binary, damaged)
        (damaged / name.strip()).write_bytes(content)
        with pytest.raises(IngestError) as exc:
            read_colmap_model(damaged, images_dir=model / "images")
        assert f"{damaged / name.strip()}: {expected}" in str(exc.value), f"not refused as expected: {exc.value}"


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


def _binary_model(folder, *, cameras=1, images=None, points=None):
    """A binary model written by hand: one PINHOLE camera; ``images`` and ``points`` as ``(count, records)``."""
    import struct

    folder.mkdir(parents=True, exist_ok=True)
    camera = struct.pack("<IiQQ4d", 1, 1, 64, 48, 50, 50, 32, 24)
    (folder / "cameras.bin").write_bytes(struct.pack("<Q", cameras) + camera)
    image = struct.pack("<I4d3dI", 1, 1, 0, 0, 0, 0, 0, 0, 1) + b"a.png\0" + struct.pack("<Q", 1)
    image += struct.pack("<2dQ", 3.0, 4.0, 1)
    count, records = images or (1, image)
    (folder / "images.bin").write_bytes(struct.pack("<Q", count) + records)
    tracked = struct.pack("<Q3d3BdQ", 1, 0.1, 0.2, 10.0, 1, 2, 3, 0.5, 1) + struct.pack("<II", 1, 0)
    rest = b"".join(struct.pack("<Q3d3BdQ", i, 0.1 * i, 0.2, 10.0, 1, 2, 3, 0.5, 0) for i in range(2, 11))
    count, records = points or (10, tracked + rest)
    (folder / "points3D.bin").write_bytes(struct.pack("<Q", count) + records)
    return folder


def test_a_binary_model_written_by_hand_reads(tmp_path):
    poses = read_colmap_model(_binary_model(tmp_path / "m"))
    assert [f.name for f in poses.frames] == ["a.png"] and len(poses.points) == 10


def test_binary_counts_beyond_the_file_are_refused_before_pycolmap_allocates(tmp_path):
    """An interrupted copy keeps the counts of the whole file: pycolmap allocated for them (GBs, or a hang), or
    read an image claiming 20 000 000 2-D points and holding none as fine."""
    import struct

    point = struct.pack("<Q3d3BdQ", 1, 0.1, 0.2, 10.0, 1, 2, 3, 0.5, 0)  # 51 bytes
    image = struct.pack("<I4d3dI", 1, 1, 0, 0, 0, 0, 0, 0, 1) + b"a.png\0"
    cases = {
        "points3D.bin: the header claims 1000 records, but its 510 bytes": {"points": (1000, point * 10)},
        "points3D.bin: point record 2 of 2 (at byte 59) claims 5000 track entries (8 bytes each), which needs "
        "40000 bytes, but only 0 are left": {"points": (2, point + point[:-8] + struct.pack("<Q", 5000))},
        "images.bin: image record 1 of 1 'a.png' (at byte 8) claims 20000000 2-D points (24 bytes each), which needs "
        "480000000 bytes, but only 0 are left": {"images": (1, image + struct.pack("<Q", 20_000_000))},
        "images.bin: the header claims 3 records, but its 78 bytes": {"images": (3, image + struct.pack("<Q", 0))},
        "images.bin: image record 1 of 1 (at byte 8), its name and 2-D point count, needs": {
            "images": (1, image[:-1] + b"abcdefghij")},
        "cameras.bin: the header claims 2 records": {"cameras": 2},
    }
    for expected, damage in cases.items():
        folder = _binary_model(tmp_path / str(len(expected)), **damage)
        with pytest.raises(IngestError) as exc:
            read_colmap_model(folder)
        assert f"{folder}/{expected}" in str(exc.value), f"not refused naming the file, record and count: {exc.value}"


def test_the_camera_param_counts_are_pycolmaps(tmp_path):
    pycolmap = pytest.importorskip("pycolmap")
    from pytest_n2r.data.colmap import _PARAM_COUNTS

    for model in pycolmap.CameraModelId.__members__.values():
        if int(model) >= 0:
            camera = pycolmap.Camera.create_from_model_id(1, model, 1.0, 10, 10)
            assert _PARAM_COUNTS[int(model)] == len(camera.params), f"{model.name}: not pycolmap's param count"


def test_a_zero_quaternion_is_refused_naming_the_file_and_image(model):
    images = model / "sparse" / "0" / "images.txt"
    images.write_text(_IMAGES.replace("1 1 0 0 0 0 0 0 1 a.jpg", "1 0 0 0 0 0 0 0 1 a.jpg"))
    with pytest.raises(IngestError) as exc:
        poses = read_colmap_model(model / "sparse" / "0")
        pytest.fail(f"a zero quaternion was read as the rotation {poses.frames[0].c2w[:3, :3].tolist()}")
    assert f"{images}: image 'a.jpg' has the quaternion (0, 0, 0, 0)" in str(exc.value)
    assert "non-zero quaternion" in str(exc.value)
