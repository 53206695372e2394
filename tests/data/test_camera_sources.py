"""Cameras of scenes trained elsewhere: the 3DGS cameras.json, a transforms.json without images and a COLMAP
model, each converted to ours (camera-to-world, OpenCV axes and pixel centres) and checked on known poses."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pytest_n2r.data import SourceFrame, write_colmap_text, write_transforms_json
from pytest_n2r.data.camera_sources import find_cameras, read_cameras
from pytest_n2r.data.gs_cameras import read_gs_cameras, write_gs_cameras
from pytest_n2r.errors import IngestError
from pytest_n2r.geometry import Camera, project

#: A camera 5 units up the world z axis looking straight down (OpenCV: its y axis along world -y).
LOOKING_DOWN = np.array([[1.0, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 5.0], [0, 0, 0, 1]])
#: A camera at (1, 2, 3) looking along world +x, its image's right along world -y: a rotation that is not its own
#: transpose (LOOKING_DOWN's is), so a reader or writer that transposes it is seen.
TURNED = np.array([[0.0, 0, 1, 1], [-1, 0, 0, 2], [0, -1, 0, 3], [0, 0, 0, 1]])


def test_a_3dgs_cameras_json_entry_is_read_as_an_opencv_camera_to_world_pose(tmp_path):
    """The reference writes ``position`` (the centre) and ``rotation`` (camera-to-world rows, OpenCV axes);
    its principal point is the image centre. A point 5 units below the camera and 1 unit along world +x is
    seen right of the centre by fx/5 pixels, on the centre row."""
    entry = {"id": 0, "img_name": "IMG_0001", "width": 64, "height": 48, "position": [0.0, 0.0, 5.0],
             "rotation": LOOKING_DOWN[:3, :3].tolist(), "fy": 40.0, "fx": 50.0}
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([entry]))
    frame = read_gs_cameras(path).frames[0]
    assert frame.name == "IMG_0001" and frame.path is None
    assert frame.camera == Camera(64, 48, 50.0, 40.0, 31.5, 23.5), f"{frame.camera}"
    np.testing.assert_array_equal(frame.c2w, LOOKING_DOWN)
    uv, z = project(np.array([[1.0, 0.0, 0.0]]), frame.camera, frame.c2w)
    np.testing.assert_allclose(uv, [[31.5 + 50.0 / 5, 23.5]])
    assert z[0] == pytest.approx(5.0)


def test_a_3dgs_rotation_is_read_as_camera_to_world_rows(tmp_path):
    entry = {"id": 0, "img_name": "a", "width": 8, "height": 6, "position": TURNED[:3, 3].tolist(),
             "rotation": TURNED[:3, :3].tolist(), "fx": 5.0, "fy": 5.0}
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([entry]))
    np.testing.assert_array_equal(read_gs_cameras(path).frames[0].c2w, TURNED)


def test_cameras_json_round_trips(tmp_path):
    """Unequal focal lengths and a rotation that is not its own transpose: a swap of either is seen in the file."""
    frames = [SourceFrame("a.png", None, Camera(30, 20, 25.0, 27.0, 14.5, 9.5), TURNED)]
    path = write_gs_cameras(tmp_path / "cameras.json", frames)
    entry = json.loads(path.read_text())[0]
    assert (entry["fx"], entry["fy"]) == (25.0, 27.0), entry
    assert entry["rotation"] == TURNED[:3, :3].tolist() and entry["position"] == [1.0, 2.0, 3.0], entry
    back = read_gs_cameras(path).frames[0]
    assert back.name == "a" and back.camera == frames[0].camera, back.camera
    np.testing.assert_allclose(back.c2w, TURNED, atol=1e-15)


@pytest.mark.parametrize("change, expected", [
    ({"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 2]]}, "field 'rotation' is not a rotation"),
    ({"rotation": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}, "field 'rotation' is not a rotation"),  # a mirror
    ({"fx": -3}, "field 'fx'=-3; expected a finite number > 0"),
    ({"position": [0, 0]}, "'position' has shape (2,)"),
    ({"width": 10.5}, "expected whole pixels"),
    ({"position": [0, float("nan"), 0]}, "contains NaN or Inf"),
    ({"width": 10**400}, "field 'width'=1000"),  # an int no float holds: was a bare OverflowError
])
def test_a_bad_cameras_json_entry_is_named(tmp_path, change, expected):
    entry = {"id": 0, "img_name": "x", "width": 8, "height": 6, "position": [0, 0, 0],
             "rotation": np.eye(3).tolist(), "fx": 5.0, "fy": 5.0} | change
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([entry]))
    with pytest.raises(IngestError) as info:
        read_gs_cameras(path)
    assert expected in str(info.value) and "[0]" in str(info.value), str(info.value)



@pytest.mark.parametrize("names", [("x", "y", "x"), (None, "camera_00000")])
def test_two_cameras_json_entries_of_one_name_are_refused_naming_both(tmp_path, names):
    """Views are looked up by name: of two views of one name only the first could ever be drawn."""
    entry = {"width": 8, "height": 6, "position": [0, 0, 0], "rotation": np.eye(3).tolist(), "fx": 5.0, "fy": 5.0}
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([entry | ({} if name is None else {"img_name": name}) for name in names]))
    with pytest.raises(IngestError) as info:
        read_gs_cameras(path)
    second = len(names) - 1
    expected = f"{path}: [0] and [{second}] both have img_name {names[second]!r}; expected one camera a name"
    assert expected in str(info.value), f"{info.value}; expected {expected!r}"


@pytest.mark.parametrize("content, expected", [
    ([], "expected a non-empty JSON list of cameras (3DGS cameras.json)"),
    ([{"id": 0, "img_name": "x", "width": 8, "height": 6, "fx": 5.0, "fy": 5.0}], "[0]"),
])
def test_a_malformed_cameras_json_gets_the_3dgs_reader_s_error(tmp_path, content, expected):
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps(content))
    with pytest.raises(IngestError) as info:
        read_cameras(path)
    assert expected in str(info.value) and "transforms" not in str(info.value), str(info.value)


@pytest.mark.parametrize("name, opening", [("cameras.json", "["), ("transforms.json", '{"frames": ')])
def test_json_nested_deeper_than_the_parser_goes_is_an_error_naming_the_file(tmp_path, name, opening):
    """A RecursionError out of the JSON parser was a bare traceback (exit 1)."""
    path = tmp_path / name
    path.write_text(" \n" + opening + "[" * 100_000 + "]" * 100_000 + ("]" if opening == "[" else "}"))
    with pytest.raises(IngestError) as info:
        read_cameras(path)
    assert f"{path}: not a readable JSON file (nested too deeply" in str(info.value), \
        f"deeply nested {name} was not refused naming the file: {info.value}"

def test_cameras_json_refuses_what_it_cannot_hold(tmp_path):
    frames = [SourceFrame("a.png", None, Camera(30, 20, 25.0, 25.0, 10.0, 9.5), np.eye(4))]
    with pytest.raises(IngestError, match="principal point off the image centre"):
        write_gs_cameras(tmp_path / "cameras.json", frames)


def test_a_transforms_json_without_images_keeps_its_frames(tmp_path):
    """nerfstudio's matrix is OpenGL camera-to-world: the same looking-down camera has its y and z flipped."""
    opengl = LOOKING_DOWN @ np.diag([1.0, -1.0, -1.0, 1.0])
    data = {"w": 64, "h": 48, "fl_x": 50.0, "fl_y": 40.0, "cx": 32.0, "cy": 24.0,
            "frames": [{"file_path": "images/a.png", "transform_matrix": opengl.tolist()}]}
    path = tmp_path / "transforms.json"
    path.write_text(json.dumps(data))
    frame = read_cameras(path).frames[0]
    assert frame.path is None and frame.camera == Camera(64, 48, 50.0, 40.0, 31.5, 23.5)
    np.testing.assert_allclose(frame.c2w, LOOKING_DOWN, atol=1e-12)
    del data["w"]
    path.write_text(json.dumps(data))
    with pytest.raises(IngestError, match="no image size; expected fields 'w' and 'h'"):
        read_cameras(path)


def test_a_colmap_model_gives_the_same_poses(tmp_path):
    """COLMAP stores world-to-camera (qvec, tvec) and pixel centres at 0.5: written and read back, the poses
    and cameras are ours again."""
    poses = [LOOKING_DOWN.copy() for _ in range(3)]
    for i, c2w in enumerate(poses):
        c2w[0, 3] = float(i)
    frames = [SourceFrame(f"{i}.png", None, Camera(64, 48, 50.0, 40.0, 31.5, 23.5), c2w) for i, c2w in enumerate(poses)]
    write_colmap_text(tmp_path / "sparse" / "0", frames)
    back = read_cameras(tmp_path).frames
    assert [f.name for f in back] == ["0.png", "1.png", "2.png"]
    for frame, c2w in zip(back, poses):
        np.testing.assert_allclose(frame.c2w, c2w, atol=1e-12, err_msg=f"pose of {frame.name}")
        assert frame.camera == frames[0].camera, f"camera of {frame.name}: {frame.camera}"


def test_cameras_are_found_where_the_trainers_put_them(tmp_path):
    run = tmp_path / "output" / "run"
    ply = run / "point_cloud" / "iteration_30000" / "point_cloud.ply"
    ply.parent.mkdir(parents=True)
    ply.write_bytes(b"ply\n")
    assert find_cameras(ply) is None
    (run.parent / "cameras.json").write_text("[]")  # three folders above the ply's: another run's, not looked at
    assert find_cameras(ply) is None, "a cameras.json three folders above the ply's folder was taken"
    (run / "cameras.json").write_text("[]")
    assert find_cameras(ply) == (run / "cameras.json").resolve()
    beside = tmp_path / "flat" / "scene.ply"
    beside.parent.mkdir()
    beside.write_bytes(b"ply\n")
    write_transforms_json(beside.parent / "transforms.json",
                          [SourceFrame("a.png", None, Camera(8, 6, 5.0, 5.0, 3.5, 2.5), np.eye(4))])
    assert find_cameras(beside) == (beside.parent / "transforms.json").resolve()


def test_an_unknown_camera_source_is_named(tmp_path):
    with pytest.raises(IngestError, match="expected a 3DGS cameras.json, a transforms.json or a COLMAP model"):
        read_cameras(tmp_path)
