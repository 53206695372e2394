"""transforms.json as other tools write and read it: instant-ngp's per-axis focal lengths and Windows separators,
nerfstudio's masks, whole-pixel sizes, and what ``n2r poses -o`` tells the user
when it writes a lens nerfstudio and instant-ngp cannot read."""

from __future__ import annotations

import json
import math
import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from pytest_n2r.cli.main import main
from pytest_n2r.data import read_transforms_json
from pytest_n2r.errors import IngestError

from .synthetic import write_transforms

#: an OpenGL camera-to-world pose: at (0, 0, 5), looking down -z
_GL_POSE = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 5.0], [0.0, 0.0, 0.0, 1.0]]


def _write(folder: Path, meta: dict, frames: list[dict]) -> Path:
    path = folder / "transforms.json"
    path.write_text(json.dumps({**meta, "frames": [{"transform_matrix": _GL_POSE, **f} for f in frames]}))
    return path


@settings(max_examples=40, deadline=None)
@given(fx=st.floats(50.0, 2000.0), angle_y=st.floats(0.05, 3.0), per_frame=st.booleans())
def test_fl_y_comes_from_camera_angle_y_when_fl_x_is_given_without_it(tmp_path_factory, fx, angle_y, per_frame):
    """instant-ngp reads each axis on its own: ``fl_x`` and ``camera_angle_y`` give ``fy = h / (2 tan(a / 2))``."""
    folder = tmp_path_factory.mktemp("angle_y")
    fields = {"fl_x": fx, "camera_angle_y": angle_y, "w": 640, "h": 480}
    meta, frame = ({}, fields) if per_frame else (fields, {})
    path = _write(folder, meta, [{"file_path": "a.png", **frame}])
    camera = read_transforms_json(path, images=False).frames[0].camera
    assert camera.fx == fx
    assert math.isclose(camera.fy, 240.0 / math.tan(angle_y / 2), rel_tol=1e-12), \
        f"fy={camera.fy} with fl_x={fx} and camera_angle_y={angle_y}: camera_angle_y was not read"


def test_fl_y_still_wins_over_camera_angle_y_and_falls_back_to_fl_x(tmp_path):
    both = _write(tmp_path, {"fl_x": 500, "fl_y": 400, "camera_angle_y": 1.0, "w": 640, "h": 480}, [{"file_path": "a"}])
    assert read_transforms_json(both, images=False).frames[0].camera.fy == 400
    alone = _write(tmp_path, {"fl_x": 500, "w": 640, "h": 480}, [{"file_path": "a"}])
    assert read_transforms_json(alone, images=False).frames[0].camera.fy == 500


def test_a_mask_path_is_warned_of_once_naming_the_file_and_the_count(corner):
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    for frame in meta["frames"][:4]:
        frame["mask_path"] = frame["file_path"].replace("images/", "masks/")
    path.write_text(json.dumps(meta))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        poses = read_transforms_json(path)
    masks = [str(w.message) for w in caught if "mask_path" in str(w.message)]
    assert len(masks) == 1, f"expected one warning about masks, got {masks}"
    assert str(path) in masks[0] and "4 of 6 frames" in masks[0] and "every pixel" in masks[0], masks[0]
    assert poses.report.get("warnings") == masks, "n2r poses and n2r fit print report['warnings']: the note is missing"


def test_no_mask_no_warning(corner):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        poses = read_transforms_json(write_transforms(corner))
    assert "warnings" not in poses.report


@pytest.mark.skipif(os.sep != "/", reason="backslashes are separators on Windows already")
def test_windows_separators_in_file_path_are_read_as_slashes(tmp_path):
    (tmp_path / "images").mkdir()
    Image.new("RGB", (64, 48)).save(tmp_path / "images" / "land.png")
    Image.new("RGB", (64, 48)).save(tmp_path / "images" / "r_0.png")
    path = _write(tmp_path, {"fl_x": 50}, [{"file_path": "images\\land.png"}, {"file_path": ".\\images\\r_0"}])
    poses = read_transforms_json(path)
    assert [f.path for f in poses.frames] == [tmp_path / "images" / "land.png", tmp_path / "images" / "r_0.png"]
    assert [f.name for f in poses.frames] == ["images\\land.png", ".\\images\\r_0"], "a frame keeps its listed name"
    assert poses.frames[0].camera.width == 64 and poses.skipped == []


@pytest.mark.skipif(os.sep != "/", reason="a backslash cannot be in a file name on Windows")
def test_a_file_whose_name_holds_a_backslash_is_read_as_written(tmp_path):
    (tmp_path / "images").mkdir()
    Image.new("RGB", (64, 48)).save(tmp_path / "images" / "a.png")
    Image.new("RGB", (32, 24)).save(tmp_path / "images\\a.png")  # a POSIX file name with a backslash in it
    frame = read_transforms_json(_write(tmp_path, {"fl_x": 50}, [{"file_path": "images\\a.png"}])).frames[0]
    assert frame.path == tmp_path / "images\\a.png" and frame.camera.width == 32


@settings(max_examples=40, deadline=None)
@given(side=st.floats(1.0, 5000.0).filter(lambda v: not v.is_integer()), key=st.sampled_from(["w", "h"]))
def test_a_size_that_is_not_whole_pixels_is_refused_naming_the_field(tmp_path_factory, side, key):
    """``w`` 640.4 used to become 640 pixels with cx shifted by 0.2 (the centre of 640.4)."""
    sizes = {"w": 640, "h": 480, key: side}
    path = _write(tmp_path_factory.mktemp("frac"), {"fl_x": 500, **sizes}, [{"file_path": "a.png"}])
    with pytest.raises(IngestError, match=rf"frames\[0\]: field '{key}'={side!r} must be a whole number of pixels"):
        read_transforms_json(path, images=False)


def test_a_whole_size_written_as_a_float_is_read(tmp_path):
    path = _write(tmp_path, {"fl_x": 500, "w": 640.0, "h": 480.0}, [{"file_path": "a.png"}])
    camera = read_transforms_json(path, images=False).frames[0].camera
    assert (camera.width, camera.height, camera.cx, camera.cy) == (640, 480, 319.5, 239.5)


def test_poses_o_says_when_it_writes_a_lens_only_n2r_reads(corner, tmp_path, capsys):
    """A rational lens is written as FULL_OPENCV (read back exactly by n2r; nerfstudio has no such model); the
    command names it where it names the file. A lens without rational terms is written as OPENCV, silently."""
    rational = write_transforms(corner, tmp_path / "rational.json", camera_model="FULL_OPENCV", k6=1e-6)
    out = tmp_path / "out" / "rational.json"
    assert main(["poses", str(rational), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"n2r poses: warning: {out} has camera_model FULL_OPENCV" in err, err
    assert "nerfstudio and instant-ngp do not" in err, err
    assert json.loads(out.read_text())["camera_model"] == "FULL_OPENCV"
    np.testing.assert_array_equal(read_transforms_json(out).frames[0].camera.distortion, (0, 0, 0, 0, 0, 0, 0, 1e-6))

    plain = write_transforms(corner, tmp_path / "plain.json", k1=0.01, k3=0.001)
    out = tmp_path / "out" / "plain.json"
    assert main(["poses", str(plain), "-o", str(out)]) == 0
    assert "FULL_OPENCV" not in capsys.readouterr().err
    assert json.loads(out.read_text())["camera_model"] == "OPENCV"
