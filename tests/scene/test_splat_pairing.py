"""A splat .ply and its cameras in one frame: nerfstudio's dataparser_transforms.json moves the capture's
cameras into the trained frame of a splatfacto export, and a ply its cameras barely see is refused, naming
both files."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pytest_n2r.cli.main import main
from pytest_n2r.data.camera_sources import read_cameras
from pytest_n2r.data.poses import PoseSet, SourceFrame
from pytest_n2r.data.trainer_frame import FrameTransform, read_dataparser_transforms
from pytest_n2r.errors import IngestError
from pytest_n2r.geometry import Camera, apply_similarity_to_pose, rotation_from_euler
from pytest_n2r.scene.splat_scene import MIN_COVERAGE, load_splat_scene, measure_coverage
from pytest_n2r.splats import Gaussians, read_ply, write_ply

from ..splats.make_data import DATA, FILES


def nerfstudio_frame(c2ws: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, float]:
    """``(T_R, T_t, scale)`` as nerfstudio's dataparser makes them by default (orientation "up", centre
    "poses", auto scale): the mean camera up to +z, the mean centre to the origin, the farthest centre
    coordinate to 1."""
    c2ws = np.asarray(c2ws)
    up = -c2ws[:, :3, 1].mean(axis=0)  # OpenCV's y is down
    up /= np.linalg.norm(up)
    v, c = np.cross(up, [0.0, 0.0, 1.0]), up[2]
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    rot = np.eye(3) + k + k @ k / (1 + c)
    t = -rot @ c2ws[:, :3, 3].mean(axis=0)
    return rot, t, 1.0 / np.abs(c2ws[:, :3, 3] @ rot.T + t).max()


def in_frame(g: Gaussians, rot: np.ndarray, t: np.ndarray, s: float) -> Gaussians:
    """The Gaussians as a trainer in the frame x -> s (rot x + t) would export them."""
    from scipy.spatial.transform import Rotation

    turned = (Rotation.from_matrix(rot) * Rotation.from_quat(g.quats.astype(np.float64)[:, [1, 2, 3, 0]])).as_quat()
    return Gaussians(means=s * (g.means.astype(np.float64) @ rot.T + t), quats=turned[:, [3, 0, 1, 2]],
                     log_scales=g.log_scales + np.float32(math.log(s)), opacity_logits=g.opacity_logits, sh=g.sh)


@pytest.fixture(scope="module")
def splatfacto(tmp_path_factory) -> dict[str, Path]:
    """object-rotated's splats exported as in nerfstudio's frame, with and without its dataparser file."""
    root = tmp_path_factory.mktemp("splatfacto")
    ply, cams = (DATA / p for p in FILES["object-rotated"])
    rot, t, s = nerfstudio_frame([f.c2w for f in read_cameras(cams).frames])
    g = in_frame(read_ply(ply), rot, t, s)
    run = root / "outputs/run"
    write_ply(run / "exports/splat/splat.ply", g)
    (run / "dataparser_transforms.json").write_text(json.dumps({"transform": np.c_[rot, t].tolist(), "scale": s}))
    write_ply(root / "bare/splat.ply", g)
    return {"with": run / "exports/splat/splat.ply", "bare": root / "bare/splat.ply", "cameras": cams,
            "dataparser": run / "dataparser_transforms.json", "ply": ply, "s": s, "rot": rot, "t": t}


def test_a_splatfacto_export_gets_its_cameras_moved_by_the_dataparser_transform(splatfacto):
    """The dataparser_transforms.json two folders above the ply is found and applied: poses move exactly, and
    the reference length is the original's times the scale (it used to pair the export with the capture's
    cameras silently: nearly empty renders)."""
    ref = load_splat_scene(splatfacto["ply"], cameras=splatfacto["cameras"])
    scene = load_splat_scene(splatfacto["with"], cameras=splatfacto["cameras"])
    s, rot, t = splatfacto["s"], splatfacto["rot"], splatfacto["t"]
    for a, b in zip(ref.views, scene.views):
        np.testing.assert_allclose(b.c2w, apply_similarity_to_pose(a.c2w, s, rot, s * t), atol=1e-9, err_msg=a.name)
    assert scene.reference_length == pytest.approx(s * ref.reference_length, rel=1e-3)
    assert any("dataparser_transforms.json" in n and f"scale {s:.6g}" in n for n in scene.notes), scene.notes
    cover = measure_coverage(scene, scene.views)
    assert cover == pytest.approx(measure_coverage(ref, ref.views), abs=0.01), cover


def test_an_explicit_dataparser_transform_is_applied(splatfacto):
    scene = load_splat_scene(splatfacto["bare"], cameras=splatfacto["cameras"],
                             dataparser_transforms=splatfacto["dataparser"])
    assert any(str(splatfacto["dataparser"]) in n for n in scene.notes), scene.notes


def test_a_ply_its_cameras_barely_see_is_refused_naming_both_files_and_the_fix(splatfacto):
    """Measured: this export covers 6.2 % of its capture's views (the ply and cameras in one frame: 81 %)."""
    with pytest.raises(IngestError) as err:
        load_splat_scene(splatfacto["bare"], cameras=splatfacto["cameras"])
    text = str(err.value)
    assert str(splatfacto["bare"]) in text and str(splatfacto["cameras"]) in text, text
    assert "dataparser_transforms.json" in text and f"expected at least {MIN_COVERAGE:.0%}" in text, text
    share = float(text.split("cover ")[1].split("%")[0])
    assert 0 < share < 100 * MIN_COVERAGE, text
    assert load_splat_scene(splatfacto["bare"], cameras=splatfacto["cameras"], min_coverage=0).views


def test_n2r_import_refuses_it_without_a_traceback_and_takes_the_transform(splatfacto, tmp_path, capsys):
    out = tmp_path / "s.n2r"
    code = main(["import", str(splatfacto["bare"]), "--cameras", str(splatfacto["cameras"]), "-o", str(out)])
    err = capsys.readouterr().err
    assert code != 0 and "Traceback" not in err and "dataparser_transforms.json" in err and not out.exists(), err
    code = main(["import", str(splatfacto["bare"]), "--cameras", str(splatfacto["cameras"]), "-o", str(out),
                 "--dataparser-transforms", str(splatfacto["dataparser"])])
    err = capsys.readouterr().err
    assert code == 0 and "note" in err and "dataparser" in err, err
    assert main(["info", str(out)]) == 0
    assert "dataparser_transforms.json" in capsys.readouterr().out


@settings(max_examples=60, deadline=None)
@given(angles=st.tuples(*[st.floats(-180, 180)] * 3), a_angles=st.tuples(*[st.floats(-180, 180)] * 3),
       shift=st.tuples(*[st.floats(-5, 5)] * 3), scale=st.floats(0.05, 5), applied_scale=st.floats(0.5, 2))
def test_a_transforms_json_applied_transform_is_undone_first(tmp_path_factory, angles, a_angles, shift, scale,
                                                             applied_scale):
    """nerfstudio saves T·A (A: the transforms.json's applied_transform) and s·applied_scale; the cameras of
    that transforms.json must move by the T the dataparser applied to them, and s."""
    rot, a_rot = rotation_from_euler(*angles), rotation_from_euler(*a_angles)
    t, a_t = np.array(shift), np.array([0.3, -0.2, 1.0])
    root = tmp_path_factory.mktemp("applied")
    tj = root / "transforms.json"
    tj.write_text(json.dumps({"applied_transform": np.c_[a_rot, a_t].tolist(), "applied_scale": applied_scale}))
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = rotation_from_euler(10, 20, 30), [1.0, 2.0, 3.0]
    poses = PoseSet([SourceFrame("a", None, Camera(8, 6, 5.0, 5.0, 4.0, 3.0), c2w)], source=str(tj),
                    kind="transforms.json")
    saved = FrameTransform(scale * applied_scale, rot @ a_rot, rot @ a_t + t, "d.json")
    moved, note = saved.apply(poses)
    np.testing.assert_allclose(moved.frames[0].c2w, apply_similarity_to_pose(c2w, scale, rot, scale * t), atol=1e-9)
    assert "applied_transform" in note


@pytest.mark.parametrize(("content", "expected"), [
    ({"transform": np.eye(4)[:3].tolist(), "scale": -1}, r"'scale' is -1; expected a finite number > 0"),
    ({"transform": [[1, 0, 0, 0]], "scale": 1}, r"'transform': expected 3 rows of 4 finite numbers"),
    ({"transform": (2 * np.eye(4)[:3]).tolist(), "scale": 1}, r"'transform': its 3x3 part is not a rotation"),
    ({"scale": 1}, r"expected a JSON object with 'transform' \(3x4\) and 'scale'"),
    ({"transform": np.eye(4)[:3].tolist(), "scale": 10**400}, r"'scale' is 100000000000… \(401 characters\); expected"),
])
def test_a_bad_dataparser_file_is_named_with_its_field(tmp_path, content, expected):
    path = tmp_path / "dataparser_transforms.json"
    path.write_text(json.dumps(content))
    with pytest.raises(IngestError, match=expected) as err:
        read_dataparser_transforms(path)
    assert str(path) in str(err.value)


def test_a_distorted_camera_warns_that_trainers_use_another_k(tmp_path):
    model = tmp_path / "sparse/0"
    model.mkdir(parents=True)
    (model / "cameras.txt").write_text("1 OPENCV 64 48 50 50 32 24 -0.25 0.05 0 0\n")
    (model / "images.txt").write_text("1 1 0 0 0 0 0 3 1 img.png\n\n")
    (model / "points3D.txt").write_text("")
    g = Gaussians(means=np.zeros((1, 3)), quats=np.array([[1.0, 0, 0, 0]]), log_scales=np.zeros((1, 3)),
                  opacity_logits=np.array([5.0]), sh=np.zeros((1, 1, 3)))
    write_ply(tmp_path / "s.ply", g)
    with pytest.warns(UserWarning, match=r"getOptimalNewCameraMatrix"):
        load_splat_scene(tmp_path / "s.ply", cameras=model)


def test_the_split_docs_do_not_claim_nerfstudios_default():
    page = (Path(__file__).resolve().parents[2] / "docs" / "splat-scenes.md").read_text(encoding="utf-8")
    assert "the `--eval` split of 3DGS and nerfstudio" not in page
    assert "train_split_fraction" in page




def test_load_scene_and_n2r_import_take_min_coverage_and_the_message_names_them(splatfacto, tmp_path, capsys):
    """The coverage check refused scenes that loaded before (an object small in a background-free capture) with
    only load_splat_scene's keyword as a way out; load_scene, n2r import and the message now name theirs."""
    from pytest_n2r.scene import load_scene

    bare, cams = splatfacto["bare"], splatfacto["cameras"]
    with pytest.raises(IngestError) as err:
        load_scene(bare, cameras=cams)
    text = str(err.value)
    assert "--min-coverage 0" in text and "min_coverage=0" in text and "'module:function'" in text, text
    assert f"load_scene({str(bare)!r}, min_coverage=0)" in text and ",:" not in text, text
    assert load_scene(bare, cameras=cams, min_coverage=0).views
    out = tmp_path / "s.n2r"
    assert main(["import", str(bare), "--cameras", str(cams), "-o", str(out), "--min-coverage", "0"]) == 0
    assert load_scene(out).views
    capsys.readouterr()


@pytest.mark.parametrize(("value", "expected"), [
    (float("nan"), r"min_coverage=nan must be finite"),
    (-0.5, r"min_coverage=-0\.5 is out of range; expected a value in \[0, 1\]"),
    (2, r"min_coverage=2\.0 is out of range; expected a value in \[0, 1\]"),
])
def test_a_bad_min_coverage_is_refused_naming_it(splatfacto, value, expected):
    """NaN or a negative share used to turn the check off silently."""
    from pytest_n2r.errors import InvalidArgument

    with pytest.raises(InvalidArgument, match=expected):
        load_splat_scene(splatfacto["ply"], cameras=splatfacto["cameras"], min_coverage=value)


def test_load_scene_refuses_splat_options_for_a_fitted_scene_file(tmp_path):
    from pytest_n2r.errors import InvalidArgument
    from pytest_n2r.scene import load_scene

    for key, value in (("min_coverage", 0.0), ("dataparser_transforms", False)):
        with pytest.raises(InvalidArgument, match=rf"{key}=.* applies to a \.ply only"):
            load_scene(tmp_path / "fitted.n2r", **{key: value})


@pytest.fixture(scope="module")
def stale(tmp_path_factory) -> dict[str, Path]:
    """wall-sh3 (a ply in its capture's frame) beside a dataparser_transforms.json of a nerfstudio run of the
    same capture: measured, the found transform leaves 5.1 % covered, the cameras alone 91 %."""
    import shutil

    root = tmp_path_factory.mktemp("stale") / "wall"
    shutil.copytree(DATA / "wall-sh3", root)
    cams = read_cameras(root / "transforms.json")
    rot, t, s = nerfstudio_frame([f.c2w for f in cams.frames])
    (root / "dataparser_transforms.json").write_text(json.dumps({"transform": np.c_[rot, t].tolist(), "scale": s}))
    return {"ply": root / "splat.ply", "dataparser": root / "dataparser_transforms.json",
            "original": DATA / FILES["wall-sh3"][0]}


def test_a_found_transform_that_empties_the_views_is_named_and_can_be_turned_off(stale, tmp_path, capsys):
    """A dataparser_transforms.json beside a ply already in the capture's frame moved its cameras and nothing
    turned the search off; the refusal now names the found file and the off switch, which loads it right."""
    from pytest_n2r.scene import load_scene

    with pytest.raises(IngestError) as err:
        load_splat_scene(stale["ply"])
    text = " ".join(str(err.value).split())
    assert f"{stale['dataparser']} was found beside the ply and applied; without it the cameras cover" in text, text
    assert "dataparser_transforms=False" in text and "--dataparser-transforms none" in text and ",:" not in text
    ref = load_splat_scene(stale["original"])
    for scene in (load_splat_scene(stale["ply"], dataparser_transforms=False),
                  load_scene(stale["ply"], dataparser_transforms=False)):
        assert not any("dataparser" in n for n in scene.notes), scene.notes
        assert scene.reference_length == pytest.approx(ref.reference_length, rel=1e-9)
        for a, b in zip(ref.views, scene.views):
            np.testing.assert_array_equal(a.c2w, b.c2w)
    out = tmp_path / "w.n2r"
    assert main(["import", str(stale["ply"]), "-o", str(out), "--dataparser-transforms", "none"]) == 0
    assert "dataparser" not in capsys.readouterr().err


def test_an_explicit_transform_is_not_second_guessed(stale):
    """Given (not found), a transform that empties the views is blamed as before, without measuring the other."""
    with pytest.raises(IngestError, match=r"The transform does not belong to this ply and these cameras"):
        load_splat_scene(stale["ply"], dataparser_transforms=stale["dataparser"])
