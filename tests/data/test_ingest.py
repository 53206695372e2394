"""The ingest entry point: dispatch, images, split, triangulated points, bounds, reference length."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from pytest_n2r.data import ingest, source_kind
from pytest_n2r.data.colmap import write_colmap_text
from pytest_n2r.data.transforms_json import read_transforms_json
from pytest_n2r.errors import IngestError
from pytest_n2r.geometry import Camera, project

from .synthetic import distance_to_corner, render, texture, write_transforms


@pytest.fixture
def capture_json(corner):
    return write_transforms(corner)


def test_transforms_json_capture(corner, capture_json):
    cap = ingest(capture_json, downscale=0.5, heldout_every=4)
    assert [v.name for v in cap.views] == [f"images/{n}" for n in corner.names]
    assert [v.split for v in cap.views] == ["heldout", "train", "train", "train", "heldout", "train"]
    for view, c2w in zip(cap.views, corner.c2ws):
        assert view.image.shape == (60, 80, 3) and view.image.dtype == np.uint8
        assert view.camera == corner.camera.resized(80, 60)
        np.testing.assert_allclose(view.c2w, c2w, atol=1e-12)
    assert cap.report["kind"] == "transforms.json" and "SIFT" in cap.report["points_method"]


def test_a_split_in_the_file_is_kept_unless_one_is_asked_for(capture_json):
    meta = json.loads(capture_json.read_text())
    names = [f["file_path"] for f in meta["frames"]]
    meta["val_filenames"] = [names[2]]
    capture_json.write_text(json.dumps(meta))
    own = ingest(capture_json, load_images=False)
    assert [v.split for v in own.views] == ["heldout" if n == names[2] else "train" for n in names]
    asked = ingest(capture_json, load_images=False, heldout_every=4)
    assert [v.split for v in asked.views] == ["heldout", "train", "train", "train", "heldout", "train"]
    meta["val_filenames"] = "all"
    capture_json.write_text(json.dumps(meta))
    with pytest.raises(IngestError, match="'val_filenames' must be a list"):
        ingest(capture_json, load_images=False)


def test_a_split_matches_the_frames_as_nerfstudio_matches_them(capture_json):
    """``./images/a.png`` in the frames and ``images/a.png`` in val_filenames are one file (nerfstudio joins both to
    the json's folder): the split must hold, not silently become every view trained on."""
    meta = json.loads(capture_json.read_text())
    for frame in meta["frames"]:
        frame["file_path"] = "./" + frame["file_path"]
    meta["val_filenames"] = [meta["frames"][2]["file_path"][2:]]
    capture_json.write_text(json.dumps(meta))
    splits = [v.split for v in ingest(capture_json, load_images=False).views]
    assert splits == ["train", "train", "heldout", "train", "train", "train"], f"the file's split was lost: {splits}"


def test_triangulated_points_lie_on_the_scene(corner, capture_json):
    cap = ingest(capture_json, load_images=False)
    assert all(v.image is None for v in cap.views)
    assert len(cap.points) > 200, f"only {len(cap.points)} points triangulated"
    off = distance_to_corner(cap.points)
    # One pixel at the median depth (~2.9) of these 150 px focal-length views is 0.02 scene units.
    assert np.median(off) < 0.01 and np.percentile(off, 95) < 0.04, (
        f"triangulated points are off the textured planes: median {np.median(off):.4f}, "
        f"95th percentile {np.percentile(off, 95):.4f} (scene size 2)"
    )
    for view in cap.views:
        _, z = project(cap.points, view.camera, view.c2w)
        assert np.mean(z > 0) > 0.99, "points behind the cameras: pose convention mix-up"


def test_reference_length_is_the_median_surface_depth(corner, capture_json):
    cap = ingest(capture_json, load_images=False)
    truth = np.median(np.concatenate([d[np.isfinite(d)] for d in corner.depths]))
    assert cap.reference_length == pytest.approx(truth, rel=0.1), (cap.reference_length, truth)


def test_bounds_hold_the_points_seen_and_are_padded(corner, capture_json):
    cap = ingest(capture_json, load_images=False)
    lo, hi = cap.bounds
    inside = np.all((cap.points >= lo) & (cap.points <= hi), axis=1)
    assert inside.mean() > 0.95
    assert np.all(lo > -0.5) and np.all(hi < 2.5), f"bounds {cap.bounds} much larger than the scene [0, 2]^3"


def test_max_size_and_downscale_combine(capture_json):
    cap = ingest(capture_json, downscale=0.5, max_size=40)
    assert cap.views[0].image.shape == (30, 40, 3)
    assert cap.views[0].camera.size == (40, 30)


def test_distortion_is_removed(corner, tmp_path):
    """Images rendered through a distorted camera come out equal to the ideal renders."""
    dist = (-0.2, 0.05, 0.001, -0.001)
    ideal = corner.camera
    textures = [texture(k) for k in range(3)]
    # Render distorted images: sample the ideal render at undistorted positions of each pixel.
    grid = np.stack(np.meshgrid(np.arange(160.0), np.arange(120.0)), -1).reshape(-1, 1, 2)
    undist = cv2.undistortPoints(grid, ideal.K, np.array(dist), P=ideal.K).reshape(120, 160, 2).astype(np.float32)
    for name, c2w in zip(corner.names, corner.c2ws):
        big = Camera(160, 120, ideal.fx, ideal.fy, ideal.cx, ideal.cy)
        rgb, _ = render(big, c2w, textures)
        distorted = cv2.remap(rgb, undist[..., 0], undist[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        cv2.imwrite(str(corner.images_dir / name), cv2.cvtColor(distorted, cv2.COLOR_RGB2BGR))
    path = write_transforms(corner, k1=dist[0], k2=dist[1], p1=dist[2], p2=dist[3])
    cap = ingest(path)
    assert cap.views[0].camera.distortion == ()
    rgb, _ = render(corner.camera, corner.c2ws[0], textures)
    err = np.abs(cap.views[0].image.astype(int) - rgb.astype(int))[10:-10, 10:-10].mean()
    raw = np.abs(cv2.cvtColor(cv2.imread(str(corner.images_dir / corner.names[0])), cv2.COLOR_BGR2RGB).astype(int)
                 - rgb.astype(int))[10:-10, 10:-10].mean()
    assert err < 0.5 * raw, f"undistorted image differs from the ideal render by {err:.1f} (distorted: {raw:.1f})"


def test_image_size_mismatch_names_the_file(corner):
    path = write_transforms(corner, w=200, h=100)
    with pytest.raises(IngestError, match=rf"{corner.names[0]}.*160x120 pixels but its camera says 200x100"):
        ingest(path)


def test_fewer_than_three_frames(corner):
    for name in corner.names[2:]:
        (corner.images_dir / name).unlink()
    with pytest.warns(UserWarning), pytest.raises(IngestError, match="only 2 registered images; at least 3"):
        ingest(write_transforms(corner))


@pytest.mark.parametrize(
    ("kwargs", "exc", "match"),
    [
        ({"downscale": 0}, ValueError, "downscale=0"),
        ({"downscale": 2}, ValueError, "downscale=2.0 is out of range"),
        ({"downscale": math.nan}, ValueError, "downscale=nan must be finite"),
        ({"max_size": 8}, ValueError, "max_size=8 is too small"),
        ({"max_size": 50.5}, TypeError, "max_size=50.5 must be an int"),
        ({"heldout_every": -1}, ValueError, "heldout_every=-1"),
    ],
)
def test_bad_arguments_name_themselves(capture_json, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        ingest(capture_json, **kwargs)


def test_missing_source(tmp_path):
    with pytest.raises(IngestError, match="does not exist"):
        ingest(tmp_path / "nothing")
    (tmp_path / "notes.txt").write_text("hi")
    with pytest.raises(IngestError, match="neither a .json file nor a video"):
        ingest(tmp_path / "notes.txt")


def test_empty_folder_is_an_images_folder_without_images(tmp_path):
    with pytest.raises(IngestError, match="holds no images"):
        ingest(tmp_path)


def test_source_kind_dispatch(corner, capture_json, tmp_path):
    assert source_kind(corner.root) == ("transforms.json", capture_json)
    assert source_kind(capture_json) == ("transforms.json", capture_json)
    assert source_kind(corner.images_dir) == ("images", corner.images_dir)
    capture_json.unlink()
    assert source_kind(corner.root) == ("images", corner.images_dir)
    poses = read_transforms_json(write_transforms(corner, path=tmp_path / "t.json"))
    write_colmap_text(corner.root / "sparse" / "0", poses)
    assert source_kind(corner.root) == ("colmap", corner.root / "sparse" / "0")


def test_colmap_source_ingests_like_the_json(corner, tmp_path):
    """A COLMAP model of the same cameras and poses (no points: they are triangulated) gives the same capture."""
    json_path = write_transforms(corner)
    poses = read_transforms_json(json_path)
    write_colmap_text(corner.root / "sparse" / "0", poses)
    json_path.unlink()
    meta_names = [n for n in corner.names]
    a = ingest(corner.root, downscale=0.5)
    assert [v.name for v in a.views] == [f"images/{n}" for n in meta_names]
    for v, c2w in zip(a.views, corner.c2ws):
        np.testing.assert_allclose(v.c2w, c2w, atol=1e-12)
        assert v.camera == corner.camera.resized(80, 60)
    assert a.report["kind"] == "colmap" and len(a.points) > 200
    assert json.loads(json.dumps(a.report))  # report is plain JSON-ready data


def test_colmap_model_without_its_images(corner, tmp_path):
    poses = read_transforms_json(write_transforms(corner))
    model = tmp_path / "a" / "b" / "c" / "d" / "model"  # too far from the images to find them
    write_colmap_text(model, poses)
    with pytest.raises(IngestError, match=r"image 'images/view_000.png' listed in the COLMAP model was not found"):
        ingest(model)


def test_undecodable_image_is_skipped_with_a_warning(corner, capture_json):
    (corner.images_dir / corner.names[1]).write_bytes(b"not a png")
    with pytest.warns(UserWarning, match=rf"skipping frame 'images/{corner.names[1]}'.*cannot be decoded"):
        cap = ingest(capture_json, downscale=0.5)
    assert [v.name for v in cap.views] == [f"images/{n}" for n in corner.names if n != corner.names[1]]
    assert cap.skipped[0][0] == f"images/{corner.names[1]}"
    assert all(v.image.shape == (60, 80, 3) for v in cap.views)


def test_too_few_decodable_images(corner, capture_json):
    for name in corner.names[:4]:
        (corner.images_dir / name).write_bytes(b"")
    with pytest.warns(UserWarning), pytest.raises(IngestError, match="only 2 images could be read; at least 3") as e:
        ingest(capture_json)
    for name in corner.names[:4]:  # every one of them, not the first failure only
        assert f"images/{name}: image file '{corner.images_dir / name}' is empty" in str(e.value), e.value


def _tag_orientation(path, orientation: int) -> None:
    """Rewrite the PNG at ``path`` with the same stored pixels and an EXIF orientation tag."""
    from PIL import Image

    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.open(path).save(path, exif=exif)


def test_a_colmap_model_describes_its_photos_as_stored(corner):
    """COLMAP ignores the EXIF orientation, so its cameras and poses describe the pixels as stored: a photo tagged
    'turned half a turn' (3) must not be turned against its pose, nor a 'quarter turn' (6) one refused."""
    poses = read_transforms_json(write_transforms(corner))
    write_colmap_text(corner.root / "sparse" / "0", poses)
    (corner.root / "transforms.json").unlink()
    stored = [cv2.cvtColor(cv2.imread(str(corner.images_dir / n)), cv2.COLOR_BGR2RGB) for n in corner.names]
    _tag_orientation(corner.images_dir / corner.names[0], 3)
    _tag_orientation(corner.images_dir / corner.names[1], 6)
    cap = ingest(corner.root)
    for k in (0, 1):
        assert cap.views[k].image.shape == stored[k].shape, \
            f"{corner.names[k]} was read as {cap.views[k].image.shape}, not as stored {stored[k].shape}"
        assert np.array_equal(cap.views[k].image, stored[k]), f"{corner.names[k]} was turned against its pose"


def test_a_colmap_camera_of_the_upright_size_is_refused_naming_the_orientation(corner, tmp_path):
    from dataclasses import replace

    poses = read_transforms_json(write_transforms(corner, path=tmp_path / "t.json"))
    poses.frames[0] = replace(poses.frames[0], camera=poses.frames[0].camera.resized(120, 160))
    write_colmap_text(corner.root / "sparse" / "0", poses)
    _tag_orientation(corner.images_dir / corner.names[0], 6)
    with pytest.raises(IngestError, match=rf"{corner.names[0]}' is 160x120 pixels but its camera says 120x160 "
                                          r"\(its pixels as stored: COLMAP ignores a photo's orientation tag"):
        ingest(corner.root, load_images=False)


def test_heldout_every_0_holds_none_out_even_where_the_source_has_no_split():
    from pytest_n2r.data.capture import split_frames

    assert split_frames([f"{k}.png" for k in range(10)], None, 0) == ["train"] * 10
