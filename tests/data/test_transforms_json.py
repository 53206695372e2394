"""Reading and writing nerfstudio / instant-ngp transforms.json, and every malformed-file error."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.data import read_transforms_json, write_transforms_json
from pytest_n2r.errors import IngestError

from .synthetic import write_transforms


def test_reads_cameras_poses_and_names(corner):
    poses = read_transforms_json(write_transforms(corner))
    assert [f.name for f in poses.frames] == [f"images/{n}" for n in corner.names]
    assert poses.kind == "transforms.json" and poses.skipped == []
    for frame, c2w in zip(poses.frames, corner.c2ws):
        np.testing.assert_allclose(frame.c2w, c2w, atol=1e-12)
        assert frame.camera == corner.camera  # cx written as cx + 0.5, read back as cx
        assert frame.path == corner.images_dir / frame.name.split("/")[1]


def test_per_frame_intrinsics_win_over_global(corner):
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    meta["frames"][1].update(fl_x=200.0, fl_y=210.0, cx=70.0, k1=0.1)
    path.write_text(json.dumps(meta))
    frames = read_transforms_json(path).frames
    cam = frames[1].camera
    assert (cam.fx, cam.fy, cam.cx, cam.distortion) == (200.0, 210.0, 69.5, (0.1, 0.0, 0.0, 0.0))
    assert frames[0].camera == corner.camera


def test_camera_angle_fallback_and_centre_default(corner):
    angle = 2 * math.atan(0.5 * 160 / 150.0)
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    for key in ("fl_x", "fl_y", "cx", "cy"):
        del meta[key]
    meta["camera_angle_x"] = angle
    path.write_text(json.dumps(meta))
    cam = read_transforms_json(path).frames[0].camera
    assert cam.fx == pytest.approx(150.0) and cam.fy == pytest.approx(150.0)
    assert (cam.cx, cam.cy) == (79.5, 59.5)


def test_camera_angle_y_gives_fy_from_the_height(corner):
    """A 160×120 photo: ``fl_y = h / (2 tan(camera_angle_y / 2))``, from the height, not the width."""
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    del meta["fl_x"], meta["fl_y"]
    meta["camera_angle_x"] = 2 * math.atan(0.5 * 160 / 150.0)
    meta["camera_angle_y"] = 2 * math.atan(0.5 * 120 / 180.0)
    path.write_text(json.dumps(meta))
    cam = read_transforms_json(path).frames[0].camera
    assert (cam.fx, cam.fy) == (pytest.approx(150.0), pytest.approx(180.0)), (cam.fx, cam.fy)


@pytest.mark.parametrize("key", ["camera_angle_x", "camera_angle_y"])
def test_a_field_of_view_in_degrees_is_refused_naming_the_field(corner, key):
    def mutate(m):
        del m["fl_x"], m["fl_y"]
        m["camera_angle_x"] = 0.9
        m[key] = 60.0  # degrees, not radians
    assert f"'{key}'=60.0 must be in (0, pi) radians" in _break(corner, mutate)


def test_a_width_that_is_not_whole_pixels_is_refused(corner):
    assert "'w'=160.5 must be a whole number of pixels" in _break(corner, lambda m: m.update(w=160.5))


def test_a_windows_file_path_is_read(corner):
    """``images\\a.png``, as a transforms.json written on Windows has it."""
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    for frame in meta["frames"]:
        frame["file_path"] = frame["file_path"].replace("/", "\\")
    path.write_text(json.dumps(meta))
    poses = read_transforms_json(path)
    assert len(poses.frames) == len(corner.names) and poses.skipped == [], poses.skipped
    assert poses.frames[0].path == corner.images_dir / corner.names[0], poses.frames[0].path


def test_size_from_the_image_when_w_h_absent(corner):
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    del meta["w"], meta["h"]
    path.write_text(json.dumps(meta))
    assert read_transforms_json(path).frames[0].camera.size == (160, 120)


def test_missing_image_is_skipped_with_a_warning_naming_it(corner):
    (corner.images_dir / corner.names[2]).unlink()
    with pytest.warns(UserWarning, match=rf"images/{corner.names[2]}.*frames\[2\] does not exist"):
        poses = read_transforms_json(write_transforms(corner))
    assert len(poses.frames) == 5
    assert poses.skipped[0][0] == f"images/{corner.names[2]}"


def test_suffixless_file_path_finds_png(corner):
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    meta["frames"][0]["file_path"] = "./images/" + corner.names[0].removesuffix(".png")
    path.write_text(json.dumps(meta))
    assert read_transforms_json(path).frames[0].path.name == corner.names[0]


def test_three_by_four_matrix_is_accepted(corner):
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    meta["frames"][0]["transform_matrix"] = meta["frames"][0]["transform_matrix"][:3]
    path.write_text(json.dumps(meta))
    np.testing.assert_allclose(read_transforms_json(path).frames[0].c2w, corner.c2ws[0], atol=1e-12)


def test_rounded_rotations_become_exact_rotations(corner):
    """A file with matrices rounded to 4 decimals is accepted, and its poses pass the strict pose check that
    scene files and rendering apply (1e-5), so a fitted scene can be saved and loaded again."""
    from pytest_n2r.geometry import check_pose

    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    for frame in meta["frames"]:
        frame["transform_matrix"] = np.round(np.asarray(frame["transform_matrix"]), 4).tolist()
    path.write_text(json.dumps(meta))
    for frame in read_transforms_json(path).frames:
        R = frame.c2w[:3, :3]
        assert np.abs(R.T @ R - np.eye(3)).max() < 1e-12, f"{frame.name}: rotation not made orthonormal"
        check_pose(frame.c2w)


def _break(corner, mutate) -> str:
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    mutate(meta)
    path.write_text(json.dumps(meta))
    with pytest.raises(IngestError) as exc:
        read_transforms_json(path)
    assert str(path) in str(exc.value), f"error does not name the file: {exc.value}"
    return str(exc.value)


def test_missing_transform_matrix_names_frame_and_field(corner):
    msg = _break(corner, lambda m: m["frames"][3].pop("transform_matrix"))
    assert "frames[3]" in msg and "'transform_matrix' is missing" in msg


def test_non_finite_matrix_names_frame(corner):
    def mutate(m):
        m["frames"][4]["transform_matrix"][0][3] = float("nan")
    msg = _break(corner, mutate)
    assert "frames[4]" in msg and "non-finite" in msg


@pytest.mark.parametrize("key", ["fl_x", "cx", "w"])
def test_an_integer_too_large_for_a_float_names_the_field(corner, key):
    def mutate(m):
        m[key] = 10**400
    msg = _break(corner, mutate)
    assert f"field {key!r}=an integer of 401 digits must be a finite number" in msg


def test_a_matrix_entry_too_large_for_a_float_names_the_frame(corner):
    def mutate(m):
        m["frames"][2]["transform_matrix"][0][3] = 10**400
    msg = _break(corner, mutate)
    assert "frames[2]" in msg and "'transform_matrix' holds a number too large for a float" in msg


@pytest.mark.parametrize("matrix", [
    np.eye(4) * 2,  # a scale
    np.diag([1.0, 1.0, -1.0, 1.0]),  # a mirror: orthonormal, determinant -1
    np.vstack([np.eye(4)[:3], [0.0, 0.0, 0.0, 2.0]]),  # a last row that is not 0 0 0 1
], ids=["scale", "mirror", "last-row"])
def test_non_rigid_matrix_is_refused(corner, matrix):
    def mutate(m):
        m["frames"][1]["transform_matrix"] = matrix.tolist()
    message = _break(corner, mutate)
    assert "frames[1]" in message and "not a rigid" in message, message


def test_wrong_matrix_shape(corner):
    def mutate(m):
        m["frames"][0]["transform_matrix"] = [[1, 0], [0, 1]]
    assert "shape (2, 2)" in _break(corner, mutate)


def test_missing_file_path(corner):
    msg = _break(corner, lambda m: m["frames"][0].pop("file_path"))
    assert "frames[0]" in msg and "'file_path'" in msg


def test_no_focal_length(corner):
    def mutate(m):
        del m["fl_x"], m["fl_y"]
    assert "'fl_x' or 'camera_angle_x'" in _break(corner, mutate)


def test_non_numeric_intrinsic(corner):
    def mutate(m):
        m["cx"] = "middle"
    assert "'cx'='middle' must be a finite number" in _break(corner, mutate)


def test_a_boolean_intrinsic_is_shown_as_the_boolean(corner):
    def mutate(m):
        m["k1"] = True
    msg = _break(corner, mutate)
    assert "'k1'=True must be a finite number" in msg, f"a boolean shown as something else: {msg}"


def test_bad_focal_value(corner):
    def mutate(m):
        m["fl_x"] = -5.0
    assert "bad intrinsics" in _break(corner, mutate)


def test_an_image_listed_twice_is_refused_naming_both_frames(corner):
    """A view is named by its file_path; a second frame of one image made two views of one name, one never drawn,
    and `n2r fit` failed only when it saved the fitted scene."""
    msg = _break(corner, lambda m: m["frames"].append(dict(m["frames"][1])))
    assert "is also frames[1]'s; expected each image once" in msg and "file_path" in msg, \
        f"a frame listing an image twice was not refused naming both frames: {msg}"


def test_missing_frames_field(corner):
    assert "'frames' is missing or empty" in _break(corner, lambda m: m.pop("frames"))


@pytest.mark.parametrize("model", ["OPENCV_FISHEYE", "FISHEYE624", "VR180_L", "OMNIDIRECTIONALSTEREO_L", "ORTHOPHOTO",
                                   "EQUIRECTANGULAR", "OPNECV", 5])
def test_a_camera_model_not_read_as_it_is_meant_is_refused_naming_it(corner, model):
    def mutate(m):
        m["camera_model"] = model
    msg = _break(corner, mutate)
    assert f"field 'camera_model'={model!r} is not supported; expected one of OPENCV, PINHOLE" in msg, \
        f"camera_model {model!r} was not refused naming the field, the value and what is accepted: {msg}"


@pytest.mark.parametrize("model", ["OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL", "opencv"])
def test_nerfstudios_pinhole_models_are_read(corner, model):
    frames = read_transforms_json(write_transforms(corner, camera_model=model)).frames
    assert frames[0].camera == corner.camera, f"camera_model {model!r} read as {frames[0].camera}"


@pytest.mark.parametrize(("where", "field"), [("top", "is_fisheye"), ("frame", "is_fisheye"), ("top", "latlong")])
def test_an_instant_ngp_lens_other_than_a_pinhole_is_refused(corner, where, field):
    def mutate(m):
        (m if where == "top" else m["frames"][2])[field] = True
    msg = _break(corner, mutate)
    assert f"field {field!r}=True declares an instant-ngp lens other than a pinhole one" in msg, \
        f"{field}: true ({where}) was not refused: {msg}"
    assert where == "top" or "frames[2]" in msg, f"the error does not name the frame: {msg}"
    assert read_transforms_json(write_transforms(corner, is_fisheye=False)).frames, "is_fisheye: false was refused"


def test_nerfstudios_k4_a_radial_term_in_r8_is_refused_not_read_as_opencvs(corner):
    """nerfstudio's OPENCV distortion is 1 + k1 r² + k2 r⁴ + k3 r⁶ + k4 r⁸ (cameras/camera_utils.py); OpenCV's k4 is
    the first term of a denominator. A k4 of one read as the other is a silently wrong lens."""
    msg = _break(corner, lambda m: m.update(k4=0.05))
    assert "field 'k4'=0.05: in nerfstudio's pinhole models k4 is a radial term in r⁸" in msg, \
        f"a non-zero nerfstudio k4 was not refused: {msg}"
    assert "field 'k5'=0.1: it is no part of nerfstudio's OPENCV" in _break(corner, lambda m: m.update(k5=0.1))
    cam = read_transforms_json(write_transforms(corner, k1=0.1, k3=0.01, k4=0.0)).frames[0].camera
    assert cam.distortion == (0.1, 0.0, 0.0, 0.0, 0.01), f"k1 and k3 read as {cam.distortion}"
    rational = read_transforms_json(write_transforms(corner, camera_model="FULL_OPENCV", k1=0.1, k4=0.05))
    assert rational.frames[0].camera.distortion == (0.1, 0.0, 0.0, 0.0, 0.0, 0.05, 0.0, 0.0), \
        f"FULL_OPENCV's k4 is not OpenCV's rational k4: {rational.frames[0].camera.distortion}"


def _split_file(corner, **fields):
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    meta["frames"][0]["file_path"] = "./" + meta["frames"][0]["file_path"]
    meta.update(fields)
    path.write_text(json.dumps(meta))
    return path


def test_the_split_is_matched_on_paths_and_test_filenames_hold_out_without_val_filenames(corner):
    names = [f"images/{n}" for n in corner.names]
    poses = read_transforms_json(_split_file(corner, val_filenames=[names[0], "./" + names[3]]))
    assert poses.heldout == {"./" + names[0], names[3]}, f"val_filenames matched {poses.heldout}"
    only_test = read_transforms_json(_split_file(corner, train_filenames=names[1:], test_filenames=[names[0]]))
    assert only_test.heldout == {"./" + names[0]}, f"test_filenames without val_filenames held out {only_test.heldout}"
    both = read_transforms_json(_split_file(corner, val_filenames=[names[1]], test_filenames=[names[2]]))
    assert both.heldout == {names[1]}, f"val_filenames did not win over test_filenames: {both.heldout}"


@pytest.mark.parametrize("field", ["val_filenames", "test_filenames", "train_filenames"])
def test_a_split_name_that_is_no_frame_is_refused_naming_the_field_and_the_name(corner, field):
    path = _split_file(corner, **{field: [f"images/{corner.names[1]}", f"photos/{corner.names[2]}"]})
    with pytest.raises(IngestError) as info:
        read_transforms_json(path)
    assert f"field {field!r} lists 'photos/{corner.names[2]}', which is no frame's file_path" in str(info.value), \
        f"a {field} name matching no frame was not refused naming it: {info.value}"


def test_written_poses_keep_their_split_with_the_file_paths_they_are_written_with(corner, tmp_path):
    names = [f"images/{n}" for n in corner.names]
    poses = read_transforms_json(_split_file(corner, val_filenames=[names[0], names[4]]))
    out = write_transforms_json(tmp_path / "elsewhere" / "poses.json", poses)
    meta = json.loads(out.read_text())
    paths = [f["file_path"] for f in meta["frames"]]
    assert meta.get("val_filenames") == [paths[0], paths[4]], f"the split was not written: {meta.get('val_filenames')}"
    assert meta["train_filenames"] == [p for k, p in enumerate(paths) if k not in (0, 4)]
    again = read_transforms_json(out)
    assert [f.name in again.heldout for f in again.frames] == [k in (0, 4) for k in range(6)], \
        "the written split does not read back as the same views"


def test_no_frame_has_its_image(corner):
    for name in corner.names:
        (corner.images_dir / name).unlink()
    with pytest.warns(UserWarning), pytest.raises(IngestError, match="none of the 6 frames has its image"):
        read_transforms_json(write_transforms(corner))


def test_not_json(tmp_path):
    path = tmp_path / "transforms.json"
    path.write_text("{not json")
    with pytest.raises(IngestError, match="not a readable JSON file"):
        read_transforms_json(path)
    path.write_text("[" * 100_000 + "]" * 100_000)  # deeper than the JSON parser goes: a RecursionError
    with pytest.raises(IngestError, match=r"transforms\.json: not a readable JSON file \(nested too deeply"):
        read_transforms_json(path)
    with pytest.raises(IngestError, match="does not exist"):
        read_transforms_json(tmp_path / "nope.json")


def test_write_then_read_keeps_names_cameras_and_poses(corner, tmp_path):
    poses = read_transforms_json(write_transforms(corner))
    out = tmp_path / "elsewhere" / "poses.json"
    write_transforms_json(out, poses, extra={"n2r": {"reference_length": 3.0}})
    again = read_transforms_json(out)
    assert [f.path.resolve() for f in again.frames] == [f.path.resolve() for f in poses.frames]
    meta = json.loads(out.read_text())
    assert meta["frames"][0]["file_path"] == f"../images/{corner.names[0]}"
    assert meta["n2r"] == {"reference_length": 3.0, "pixels": "stored"}  # another tool's file: read as stored
    for a, b in zip(again.frames, poses.frames):
        assert a.camera == b.camera
        np.testing.assert_allclose(a.c2w, b.c2w, atol=1e-12)
    assert not list(out.parent.glob(".*tmp")), "temporary file left behind"


def test_write_per_frame_intrinsics_when_cameras_differ(corner, tmp_path):
    from dataclasses import replace

    poses = read_transforms_json(write_transforms(corner))
    poses.frames[0] = replace(poses.frames[0], camera=poses.frames[0].camera.resized(80, 60))
    out = write_transforms_json(tmp_path / "t.json", poses)
    meta = json.loads(out.read_text())
    assert "fl_x" not in meta and meta["frames"][0]["w"] == 80
    assert read_transforms_json(out).frames[0].camera == poses.frames[0].camera


@st.composite
def _frames(draw):
    from pytest_n2r.data import SourceFrame
    from pytest_n2r.geometry import Camera, Transform

    dist = draw(st.sampled_from([(), (0.1, -0.02, 0.001, 0.002), (0.1, -0.02, 0.001, 0.002, 0.01),
                                 (0.1, -0.02, 0.001, 0.002, 0.01, 0.3, -0.05, 0.002)]))
    cam = Camera(draw(st.integers(16, 4000)), draw(st.integers(16, 4000)), draw(st.floats(10, 5000)),
                 draw(st.floats(10, 5000)), draw(st.floats(-100, 4000)), draw(st.floats(-100, 4000)), dist)
    angles = st.floats(-179, 179)
    return [
        SourceFrame(f"img_{k}.jpg", None, cam, Transform(draw(angles), draw(st.floats(-90, 90)), draw(angles),
                                                          *[draw(st.floats(-100, 100)) for _ in range(3)]).matrix())
        for k in range(draw(st.integers(1, 4)))
    ]


@settings(max_examples=30, deadline=None)
@given(frames=_frames())
def test_write_read_round_trip_property(tmp_path_factory, frames):
    from pytest_n2r.data.colmap import read_colmap_model, write_colmap_text

    folder = tmp_path_factory.mktemp("rt")
    for f in frames:
        (folder / f.name).write_bytes(b"")
    json_back = read_transforms_json(write_transforms_json(folder / "t.json", frames)).frames
    write_colmap_text(folder / "sparse", frames)
    colmap_back = read_colmap_model(folder / "sparse", images_dir=folder).frames
    for back in (json_back, sorted(colmap_back, key=lambda f: int(f.name[4:-4]))):
        assert [f.name for f in back] == [f.name for f in frames]
        for a, b in zip(frames, back):
            # cx, cy go through +0.5 on writing and -0.5 on reading: equal up to one rounding step
            ca, cb = a.camera.to_dict(), b.camera.to_dict()
            assert ca.pop("cx") == pytest.approx(cb.pop("cx"), abs=1e-9)
            assert ca.pop("cy") == pytest.approx(cb.pop("cy"), abs=1e-9)
            assert ca == cb
            np.testing.assert_allclose(b.c2w, a.c2w, atol=1e-9 * (1 + np.abs(a.c2w).max()))


def test_a_photo_that_is_a_link_keeps_its_own_file_path(corner, tmp_path):
    """``n2r poses DIR -o t.json`` with a link among the photos wrote both frames as the link's target: a file n2r
    refused to read back (two frames with the same file_path)."""
    import os
    from dataclasses import replace

    poses = read_transforms_json(write_transforms(corner))
    link = corner.images_dir / "link.png"
    os.symlink(corner.names[0], link)
    poses.frames[1] = replace(poses.frames[1], name="link.png", path=link)
    out = write_transforms_json(tmp_path / "out" / "t.json", poses)
    assert json.loads(out.read_text())["frames"][1]["file_path"] == "../images/link.png"
    names = [f.name for f in read_transforms_json(out).frames]  # read back: each frame its own photo
    assert names[:2] == [f"../images/{corner.names[0]}", "../images/link.png"]


def test_two_frames_of_one_photo_are_refused_before_anything_is_written(corner, tmp_path):
    from dataclasses import replace

    poses = read_transforms_json(write_transforms(corner))
    poses.frames[2] = replace(poses.frames[2], path=poses.frames[0].path)
    with pytest.raises(IngestError, match=rf"cannot write .*t\.json: frames 0 \('images/{corner.names[0]}'\) and 2 "
                                          rf"\('images/{corner.names[2]}'\) would both have file_path "
                                          rf"'\.\./images/{corner.names[0]}'; each frame needs a photo of its own"):
        write_transforms_json(tmp_path / "out" / "t.json", poses)
    assert not (tmp_path / "out" / "t.json").exists()
