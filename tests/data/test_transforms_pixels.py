"""A transforms.json's photos with an EXIF orientation tag, read as the file's writer reads them: upright in a file
n2r wrote, as stored in any other (nerfstudio and instant-ngp ignore the tag), and ``n2r poses -o`` exact for both."""

from __future__ import annotations

import contextlib
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image

from pytest_n2r.cli.main import main
from pytest_n2r.data import SourceFrame, ingest, read_transforms_json, write_colmap_text, write_transforms_json
from pytest_n2r.errors import IngestError

from .synthetic import SyntheticCapture, write_transforms

_RED = (255, 0, 0)
#: the marker's pixel (OpenCV pixel centres) in photo 0 as stored: off the centre, so any turn moves it
_MARKER = (112, 36)


def _tag(path: Path, orientation: int, pixels: np.ndarray | None = None) -> None:
    """Rewrite the photo at ``path`` with ``pixels`` (default: its own, as stored) and the EXIF orientation tag."""
    exif = Image.Exif()
    exif[0x0112] = orientation
    image = Image.open(path) if pixels is None else Image.fromarray(pixels)
    image.convert("RGB").save(path, exif=exif)


def _stored(path: Path) -> np.ndarray:
    """The photo's pixels as stored (Pillow does not apply the tag without ``exif_transpose``)."""
    return np.asarray(Image.open(path).convert("RGB"))


def _mark(path: Path) -> None:
    """Draw a 3x3 red square centred on :data:`_MARKER` into the stored pixels of the photo at ``path``."""
    pixels = _stored(path).copy()
    u, v = _MARKER
    pixels[v - 1:v + 2, u - 1:u + 2] = _RED
    Image.fromarray(pixels).save(path)


def _marker_at(image: np.ndarray) -> tuple[float, float]:
    """``(u, v)``: the centre of the pure red pixels of ``image`` (the marker)."""
    v, u = np.nonzero(np.all(image == _RED, axis=-1))
    return float(u.mean()), float(v.mean())


def _point_behind_marker(corner: SyntheticCapture, depth: float = 2.0) -> np.ndarray:
    """A world point on the ray of the marker's pixel in photo 0, ``depth`` in front of its camera (the corner's own
    camera and pose: the truth the transforms.json is written from)."""
    cam, u, v = corner.camera, *_MARKER
    ray = np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0]) * depth
    return corner.c2ws[0][:3, :3] @ ray + corner.c2ws[0][:3, 3]


def _project(camera, c2w: np.ndarray, point: np.ndarray) -> tuple[float, float]:
    x, y, z = c2w[:3, :3].T @ (point - c2w[:3, 3])
    return camera.fx * x / z + camera.cx, camera.fy * y / z + camera.cy


def _foreign_json(corner: SyntheticCapture, *, sized: bool) -> Path:
    """nerfstudio's transforms.json of the corner (no ``n2r`` block), with or without ``w`` and ``h``."""
    path = write_transforms(corner)
    if not sized:
        meta = json.loads(path.read_text())
        del meta["w"], meta["h"]
        path.write_text(json.dumps(meta))
    return path


@pytest.mark.parametrize("sized", [True, False], ids=["w-h-stored", "no-w-h"])
@pytest.mark.parametrize("orientation", [3, 6])
def test_another_tools_file_describes_the_stored_pixels(corner, orientation, sized):
    """nerfstudio and instant-ngp read a photo's pixels as stored: a known point projects, through the camera and pose
    as given, onto the marker drawn into the stored image, whatever the tag says (6: a quarter turn, 3: a half turn,
    whose upright size is the stored one)."""
    first = corner.images_dir / corner.names[0]
    _mark(first)
    _tag(first, orientation)
    stored = _stored(first)
    point = _point_behind_marker(corner)
    with warnings.catch_warnings():  # the warning has its own test below
        warnings.simplefilter("ignore")
        capture = ingest(_foreign_json(corner, sized=sized))
    view = capture.views[0]
    assert (view.camera.width, view.camera.height) == (160, 120), "the camera is not that of the stored photo"
    assert view.image.shape == stored.shape
    np.testing.assert_array_equal(view.image, stored)
    u, v = _project(view.camera, view.c2w, point)
    assert abs(u - _MARKER[0]) < 1e-6 and abs(v - _MARKER[1]) < 1e-6
    assert _marker_at(view.image) == _MARKER


def _upright_n2r_json(corner: SyntheticCapture, orientation: int) -> Path:
    """The corner's renders saved turned with ``orientation`` (so they show as rendered) and a transforms.json n2r
    wrote of their upright cameras, as ``n2r poses`` of photos structure from motion read upright."""
    for name in corner.names:
        render = _stored(corner.images_dir / name)
        stored = np.rot90(render, 1) if orientation == 6 else np.rot90(render, 2)  # tag 6 turns it back clockwise
        _tag(corner.images_dir / name, orientation, np.ascontiguousarray(stored))
    frames = [SourceFrame(name=n, path=corner.images_dir / n, camera=corner.camera, c2w=c)
              for n, c in zip(corner.names, corner.c2ws)]
    return write_transforms_json(corner.root / "n2r.json", frames, extra={"n2r": {"source": "images"}})


@pytest.mark.parametrize("orientation", [3, 6])
def test_a_file_n2r_wrote_reads_its_photos_upright_through_poses_o(corner, tmp_path, orientation, recwarn, capsys):
    renders = [_stored(corner.images_dir / n) for n in corner.names]
    path = _upright_n2r_json(corner, orientation)
    out = tmp_path / "out" / "again.json"
    assert main(["poses", str(path), "-o", str(out)]) == 0
    assert (f"n2r poses: warning: {out} describes its photos upright ({len(corner.names)} of them turned by an EXIF "
            "tag or a HEIF rotation)") in capsys.readouterr().err, "the file other tools misread was not said"
    for source in (path, out):
        capture = ingest(source)
        for view, render, c2w in zip(capture.views, renders, corner.c2ws):
            assert view.camera == corner.camera
            np.testing.assert_allclose(view.c2w, c2w, atol=1e-9)
            np.testing.assert_array_equal(view.image, render)
    assert not [w for w in recwarn if "EXIF orientation" in str(w.message)], "an n2r file's tags were warned of"
    # an n2r file without w, h (edited by hand): the size is the upright photo's, as n2r wrote the cameras
    meta = json.loads(path.read_text())
    del meta["w"], meta["h"]
    path.write_text(json.dumps(meta))
    camera = read_transforms_json(path).frames[0].camera
    assert (camera.width, camera.height) == (160, 120)
    assert json.loads(out.read_text())["n2r"]["pixels"] == "upright"
    assert read_transforms_json(out).pixels == "upright"


@pytest.mark.filterwarnings("ignore:.*EXIF orientation tag")
@pytest.mark.parametrize("source", ["colmap", "transforms.json"])
def test_poses_o_of_stored_pixels_reads_back_to_the_same_cameras_and_images(corner, tmp_path, source):
    """``n2r poses SOURCE -o out.json`` of a source that describes the pixels as stored (a COLMAP model, another
    tool's transforms.json) writes ``n2r.pixels`` "stored": out.json gives the same cameras, poses and images."""
    _tag(corner.images_dir / corner.names[0], 3)
    _tag(corner.images_dir / corner.names[1], 6)
    path = write_transforms(corner)
    if source == "colmap":
        write_colmap_text(corner.root / "sparse" / "0", read_transforms_json(path))
        path.unlink()
        path = corner.root
    out = tmp_path / "out" / "poses.json"
    assert main(["poses", str(path), "-o", str(out)]) == 0
    given, again = ingest(path), ingest(out)
    for a, b, name in zip(again.views, given.views, corner.names):
        assert a.camera == b.camera
        np.testing.assert_allclose(a.c2w, b.c2w, atol=1e-9)
        np.testing.assert_array_equal(a.image, b.image)
        np.testing.assert_array_equal(a.image, _stored(corner.images_dir / name))
    assert json.loads(out.read_text())["n2r"]["pixels"] == "stored"


def test_the_warning_names_the_file_and_how_many_photos_have_a_tag(corner, capsys):
    _tag(corner.images_dir / corner.names[2], 6)
    _tag(corner.images_dir / corner.names[4], 8)
    path = write_transforms(corner)
    expected = f"{path}: 2 of 6 photos have an EXIF orientation tag; read as stored (the tag ignored;"
    with pytest.warns(UserWarning, match=re.escape(expected)) as caught:
        poses = read_transforms_json(path)
    assert len([w for w in caught if "EXIF orientation" in str(w.message)]) == 1, "warned more than once"
    assert [w for w in poses.report["warnings"] if w.startswith(expected)]
    assert poses.pixels == "stored"
    assert main(["poses", str(path)]) == 0
    assert f"n2r poses: warning: {expected}" in capsys.readouterr().err


def _photo(path: Path, orientation: int) -> None:
    """A 64x48 JPEG (stored landscape) with the EXIF orientation tag ``orientation``."""
    exif = Image.Exif()
    exif[0x0112] = orientation
    Image.new("RGB", (64, 48), (90, 120, 150)).save(path, exif=exif.tobytes())


@settings(max_examples=30, deadline=None)
@given(orientation=st.integers(1, 8), n2r=st.booleans())
def test_without_w_h_the_size_is_that_of_the_pixels_the_writer_read(tmp_path_factory, orientation, n2r):
    """The stored size for another tool's file, the upright one (sides swapped by a quarter turn, 5 to 8) for n2r's;
    never refused for the tag (the refusal of a tagged photo without ``w`` and ``h`` is gone)."""
    folder = tmp_path_factory.mktemp("size")
    _photo(folder / "p.jpg", orientation)
    meta = {"fl_x": 50, "frames": [{"file_path": "p.jpg", "transform_matrix": np.eye(4).tolist()}]}
    if n2r:
        meta["n2r"] = {"source": "photos"}
    (folder / "transforms.json").write_text(json.dumps(meta))
    warned = n2r or orientation == 1
    with contextlib.nullcontext() if warned else pytest.warns(UserWarning, match="1 of 1 photos have an EXIF"):
        poses = read_transforms_json(folder / "transforms.json")
    camera = poses.frames[0].camera
    turned = n2r and orientation >= 5
    assert (camera.width, camera.height) == ((48, 64) if turned else (64, 48))
    assert poses.pixels == ("upright" if n2r else "stored")


def test_an_n2r_block_with_another_pixels_is_refused_naming_the_field(tmp_path):
    _photo(tmp_path / "p.jpg", 1)
    meta = {"fl_x": 50, "n2r": {"pixels": "sideways"},
            "frames": [{"file_path": "p.jpg", "transform_matrix": np.eye(4).tolist()}]}
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    with pytest.raises(IngestError, match=r"transforms\.json: field 'n2r\.pixels'='sideways' is not one of 'upright', "
                                          r"'stored'"):
        read_transforms_json(tmp_path / "transforms.json")


def test_a_corrupt_heic_among_the_photos_is_skipped_not_the_whole_file(corner):
    """Counting the photos shown turned read every header, and a HEIC photo cut short raised there: the whole
    transforms.json failed to load where the frame alone had been skipped."""
    bad = corner.images_dir / corner.names[3]
    path = write_transforms(corner)
    meta = json.loads(path.read_text())
    meta["frames"][3]["file_path"] = meta["frames"][3]["file_path"].rsplit(".", 1)[0] + ".heic"
    path.write_text(json.dumps(meta))
    bad.with_suffix(".heic").write_bytes(b"\x00\x00\x00\x18ftypheic\x00\x00\x00\x00" + b"\x00" * 20)  # cut short
    with pytest.warns(UserWarning, match=r"skipping frame 'images/view_003\.heic': .* cannot be decoded as a HEIF"):
        captured = ingest(path)
    assert len(captured.views) == len(corner.names) - 1, [v.name for v in captured.views]


def test_poses_o_replaces_only_its_own_output_not_a_file_with_an_n2r_pixels_block(corner, tmp_path):
    """Any file n2r writes of turned photos records n2r.pixels, a phone capture's too; n2r poses took every file with
    an n2r block for its own output and replaced it without --force."""
    theirs = tmp_path / "capture.json"
    theirs.write_text(json.dumps({"frames": [], "n2r": {"pixels": "upright"}}))
    assert main(["poses", str(write_transforms(corner)), "-o", str(theirs)]) == 2
    assert json.loads(theirs.read_text()) == {"frames": [], "n2r": {"pixels": "upright"}}, "the file was replaced"
    ours = tmp_path / "poses.json"
    assert main(["poses", str(write_transforms(corner)), "-o", str(ours)]) == 0
    assert main(["poses", str(write_transforms(corner)), "-o", str(ours)]) == 0, "its own output needs no --force"


def test_write_records_upright_pixels_for_tagged_photos_without_an_n2r_block(tmp_path):
    """Upright cameras of tagged photos written without ``extra``: the ``n2r`` block is made for them, or the file
    would read back as another tool's (stored pixels) and its cameras would land on the photos turned a quarter."""
    from pytest_n2r.data.poses import PoseSet
    from pytest_n2r.geometry import Camera

    frames = []
    for k in range(3):
        photo = tmp_path / f"p{k}.jpg"
        Image.fromarray(np.full((8, 12, 3), 100, np.uint8)).save(photo)  # stored 12×8: upright 8×12 once tagged
        _tag(photo, 6)
        c2w = np.eye(4)
        c2w[0, 3] = k
        frames.append(SourceFrame(name=photo.name, path=photo, camera=Camera(8, 12, 10.0, 10.0, 3.5, 5.5), c2w=c2w))
    out = write_transforms_json(tmp_path / "transforms.json", PoseSet(frames=frames, pixels="upright"))
    block = json.loads(out.read_text()).get("n2r")
    assert block == {"pixels": "upright"}, f"the written n2r block: {block}"
    assert read_transforms_json(out).pixels == "upright"
