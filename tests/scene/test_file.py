"""Scene files: round trips, deterministic bytes, atomic writes, and a clear error for every kind of bad file."""

from __future__ import annotations

import dataclasses
import io
import json
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
import safetensors.torch
import torch

from pytest_n2r.errors import InvalidArgument, SceneFileError
from pytest_n2r.field.config import FieldConfig
from pytest_n2r.geometry import Camera
from pytest_n2r.render.field_render import FieldRenderer
from pytest_n2r.scene import SceneView, read_scene_file, save_scene
from pytest_n2r.scene.schema import FIELD_FILE, FORMAT_VERSION, SCENE_JSON

from .conftest import random_field, tiny_views

REPORT = {"psnr": 21.5, "ssim": float("nan"), "heldout": [{"view": "frame_000.png", "psnr": float("inf")}]}
CONFIG = FieldConfig(resolutions=(8, 12), stage_fractions=(0.5,))


def write(path: Path, field=None, views=None, **kwargs) -> Path:
    """The test scene (random field, four views) saved at ``path``."""
    return save_scene(path, field or random_field(), CONFIG, views or tiny_views(), REPORT, reference_length=3.0,
                      **kwargs)


def test_a_loaded_scene_renders_bit_identically_to_the_quantized_field(tmp_path):
    field = random_field()
    scene_file = read_scene_file(write(tmp_path / "s.n2r", field))
    want, got = FieldRenderer(field.quantized()), FieldRenderer(scene_file.field)
    for view in scene_file.views[:2]:
        expected = want.render(view.c2w, view.camera, ("rgb", "depth", "opacity"))
        actual = got.render(view.c2w, view.camera, ("rgb", "depth", "opacity"))
        assert 0.05 < expected["opacity"].mean() < 0.95, "the test field should be neither empty nor solid"
        for name, array in expected.items():
            same = array.view(np.uint8) == actual[name].view(np.uint8)
            assert same.all(), f"{name} of view {view.name}: {np.count_nonzero(~same)} bytes differ after a round trip"


def test_views_scale_config_and_report_come_back(tmp_path):
    views = tiny_views()
    scene_file = read_scene_file(write(tmp_path / "s.n2r", views=views, metres_per_unit=0.25))
    assert [(v.index, v.name, v.split, v.camera) for v in scene_file.views] == \
        [(i, v.name, v.split, v.camera) for i, v in enumerate(views)]
    for saved, loaded in zip(views, scene_file.views):
        assert np.array_equal(saved.c2w, loaded.c2w), f"{saved.name}: pose changed in the round trip"
        error = np.abs(saved.image.astype(int) - loaded.image).mean()
        assert loaded.image.dtype == np.uint8 and error < 2.0, f"{saved.name}: JPEG copy is off by {error:.2f} levels"
    assert (scene_file.reference_length, scene_file.metres_per_unit, scene_file.config) == (3.0, 0.25, CONFIG)
    assert scene_file.report == {"psnr": 21.5, "ssim": None, "heldout": [{"view": "frame_000.png", "psnr": None}]}, \
        "non-finite report values must be stored as null (strict JSON)"
    assert scene_file.images_stored == 4 and scene_file.version == FORMAT_VERSION


@pytest.mark.parametrize("random_background, expected", [(True, 0.5), (False, 0.0), (None, 0.0)])
def test_a_file_without_a_field_background_gets_the_one_it_was_fitted_over(tmp_path, random_background, expected):
    """Files written before fields stored their background: a fit with ``random_background`` on renders
    over mid-grey, an older one (no such setting: it was fitted over black) over black."""
    def edit(data):
        del data["field"]["background"]
        if random_background is None:
            del data["config"]["random_background"]
        else:
            data["config"]["random_background"] = random_background

    old = rewrite(write(tmp_path / "new.n2r"), tmp_path / "old.n2r", edit_json=edit)
    assert read_scene_file(old).field.background == (expected,) * 3


def test_images_false_skips_the_photos_and_no_images_stores_none(tmp_path):
    assert all(v.image is None for v in read_scene_file(write(tmp_path / "a.n2r"), images=False).views)
    stored = read_scene_file(write(tmp_path / "b.n2r", images=False))
    assert stored.images_stored == 0 and all(v.image is None for v in stored.views)
    assert not [n for n in zipfile.ZipFile(tmp_path / "b.n2r").namelist() if n.startswith("images/")]


def test_the_bytes_depend_on_the_content_only(tmp_path, monkeypatch):
    first = write(tmp_path / "a.n2r").read_bytes()
    monkeypatch.setattr(time, "time", lambda: 2_000_000_000.0)  # a zip stamped with "now" would differ
    monkeypatch.setattr(time, "localtime", lambda *a: time.struct_time((2033, 5, 18, 3, 33, 20, 2, 138, 0)))
    second = write(tmp_path / "b.n2r").read_bytes()
    assert first == second, "saving the same scene twice gave different bytes"
    other = write(tmp_path / "c.n2r", random_field(seed=1)).read_bytes()
    assert other != first, "a different field gave the same bytes"


def test_a_failed_save_leaves_the_old_file_and_no_temporary(tmp_path):
    path = write(tmp_path / "s.n2r")
    before = path.read_bytes()
    views = tiny_views()
    views[2] = type(views[2])(2, "bad.png", views[2].camera, views[2].c2w, "train", np.zeros((16, 20), np.float32))
    with pytest.raises(InvalidArgument, match=r"view 'bad.png': image is float32 \(16, 20\); expected H×W×3 uint8"):
        write(path, views=views)
    assert path.read_bytes() == before, "a failed save changed the existing file"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.n2r"], "a failed save left files behind"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"reference_length": None}, r"reference_length is required when views are passed without a Capture"),
        ({"views": []}, r"holds no views"),
        ({"image_quality": 0}, r"image_quality=0; expected an integer in 1..100"),
        ({"bounds": np.zeros(3)}, r"bounds has shape \(3,\); expected a finite \(2, 3\) box"),
        ({"views": [SceneView(i, "same.png", v.camera, v.c2w, v.split) for i, v in enumerate(tiny_views(3, False))]},
         r"views \[0\] and \[1\] are both named 'same.png'; a scene file holds one view a name"),
    ],
)
def test_bad_save_arguments_are_named(tmp_path, kwargs, message):
    views = kwargs.pop("views", tiny_views())
    args = {"reference_length": 3.0, **kwargs}
    with pytest.raises(InvalidArgument, match=message):
        save_scene(tmp_path / "s.n2r", random_field(), CONFIG, views, {}, **args)


# -- bad files ---------------------------------------------------------------------------------------------------
def rewrite(src: Path, dst: Path, *, edit_json=None, replace: dict[str, bytes | int] | None = None,
            drop: tuple[str, ...] = ()) -> Path:
    """A copy of the scene file ``src`` with ``scene.json`` edited, members replaced (an int: that many zero
    bytes, streamed, so a member can inflate to gigabytes) or dropped."""
    replace = dict(replace or {})
    with zipfile.ZipFile(src) as archive, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as out:

        def put(name: str, payload: bytes | int) -> None:
            if isinstance(payload, int):
                with out.open(name, "w", force_zip64=True) as member:
                    for _ in range(payload // 2**20):
                        member.write(bytes(2**20))
            else:
                out.writestr(name, payload)

        for name in archive.namelist():
            if name in drop:
                continue
            payload = replace.pop(name, archive.read(name))
            if name == SCENE_JSON and edit_json is not None:
                data = json.loads(payload)
                edit_json(data)
                payload = json.dumps(data).encode()
            put(name, payload)
        for name, payload in replace.items():
            put(name, payload)
    return dst


def tensors_with(**changes) -> bytes:
    tensors = random_field().tensors()
    for name, value in changes.items():
        if value is None:
            del tensors[name]
        else:
            tensors[name] = value
    return safetensors.torch.save(tensors)


def pickled_field() -> bytes:
    buffer = io.BytesIO()
    torch.save(random_field().tensors(), buffer)
    return buffer.getvalue()


def _set(key, value):
    return lambda data: data.__setitem__(key, value)


def _frame(i, key, value=None):
    def edit(data):
        if value is None:
            del data["frames"][i][key]
        else:
            data["frames"][i][key] = value
    return edit


BAD_FILES = {
    "not a zip": (lambda good, bad: bad.write_bytes(b"PK but not really"), r"not a zip archive, or truncated"),
    "truncated": (lambda good, bad: bad.write_bytes(good.read_bytes()[: good.stat().st_size // 2]),
                  r"not a zip archive, or truncated"),
    "missing": (lambda good, bad: None, r"no such scene file"),
    "no scene.json": (lambda good, bad: rewrite(good, bad, drop=(SCENE_JSON,)), r"the archive has no 'scene.json'"),
    "scene.json not JSON": (lambda good, bad: rewrite(good, bad, replace={SCENE_JSON: b"{oops"}),
                            r"scene.json is not valid JSON"),
    "other format": (lambda good, bad: rewrite(good, bad, edit_json=_set("format", "nerfstudio")),
                     r"format='nerfstudio'; expected 'pytest-n2r scene' \(this is not a pytest-n2r scene file\)"),
    "newer version": (lambda good, bad: rewrite(good, bad, edit_json=_set("version", FORMAT_VERSION + 1)),
                      (rf"format version {FORMAT_VERSION + 1}; this pytest-n2r reads version {FORMAT_VERSION} "
                       r"\(it was written by a newer pytest-n2r; upgrade")),
    "older version": (lambda good, bad: rewrite(good, bad, edit_json=_set("version", 0)),
                      r"format version 0; .*refit the scene"),
    "missing key": (lambda good, bad: rewrite(good, bad, edit_json=lambda d: d.pop("reference_length")),
                    r"scene.json is missing the keys \['reference_length'\]"),
    "frame without pose": (lambda good, bad: rewrite(good, bad, edit_json=_frame(1, "c2w")),
                           r"frames\[1\] has no 'c2w' key"),
    "frame with a bad pose": (lambda good, bad: rewrite(good, bad, edit_json=_frame(2, "c2w", [[1, 0], [0, 1]])),
                              r"frames\[2\].c2w must have shape \(4 4\)"),
    "two frames of one name": (lambda good, bad: rewrite(good, bad, edit_json=_frame(2, "name", "frame_000.png")),
                               r"scene.json frames\[0\] and frames\[2\] are both named 'frame_000.png'"),
    "bad split": (lambda good, bad: rewrite(good, bad, edit_json=_frame(0, "split", "test")),
                  r"frames\[0\].split='test'; expected one of \('train', 'heldout'\)"),
    "bad reference length": (lambda good, bad: rewrite(good, bad, edit_json=_set("reference_length", -1)),
                             r"reference_length=-1; expected a finite number > 0"),
    "bad config": (lambda good, bad: rewrite(good, bad, edit_json=lambda d: d["config"].update(warp=9)),
                   r"'config' is not a valid FieldConfig \(.*unknown keys \['warp'\]"),
    "no field": (lambda good, bad: rewrite(good, bad, drop=(FIELD_FILE,)), r"the archive has no 'field.safetensors'"),
    "pickled field": (lambda good, bad: rewrite(good, bad, replace={FIELD_FILE: pickled_field()}),
                      r"field.safetensors is not a valid safetensors file"),
    "missing tensor": (lambda good, bad: rewrite(good, bad, replace={FIELD_FILE: tensors_with(vertex_values=None)}),
                       r"field.safetensors: field tensors \['vertex_values'\] are missing"),
    "mis-shaped tensor": (lambda good, bad: rewrite(
        good, bad, replace={FIELD_FILE: tensors_with(occupancy=torch.ones((5, 5, 5), dtype=torch.uint8))}),
        r"tensor 'occupancy' is torch.uint8 \(5, 5, 5\); expected torch.uint8 \(11, 11, 11\)"),
    "image that does not decode": (
        lambda good, bad: rewrite(good, bad, replace={"images/frame_001.jpg": b"\xff\xd8junk"}),
        r"images/frame_001.jpg \(the photo of frame 'frame_001.png'\) does not decode"),
    "image of the wrong size": (lambda good, bad: rewrite(
        good, bad, replace={"images/frame_003.jpg": zipfile.ZipFile(write(bad.with_name("small.n2r"), views=[
            type(v)(v.index, v.name, v.camera.resized(10, 8), v.c2w, v.split, v.image[::2, ::2].copy())
            for v in tiny_views()])).read("images/frame_003.jpg")}),
        r"images/frame_003.jpg is 10x8 pixels; frame 'frame_003.png' has a 20x16 camera"),
}


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_a_bad_file_is_a_scene_file_error_saying_what_is_wrong(tmp_path, case):
    make, message = BAD_FILES[case]
    good = write(tmp_path / "good.n2r")
    bad = tmp_path / "bad.n2r"
    make(good, bad)
    with pytest.raises(SceneFileError, match=message) as info:
        read_scene_file(bad)
    assert str(bad) in str(info.value), f"the error does not name the file: {info.value}"


def test_a_corrupt_member_is_named(tmp_path):
    good = write(tmp_path / "good.n2r")
    data = bytearray(good.read_bytes())
    with zipfile.ZipFile(good) as archive:
        info = archive.getinfo(FIELD_FILE)
    start = info.header_offset + 30 + len(info.filename) + len(info.extra)
    for i in range(start + 10, start + 60):
        data[i] ^= 0x5A
    bad = tmp_path / "bad.n2r"
    bad.write_bytes(bytes(data))
    with pytest.raises(SceneFileError, match=r"'field.safetensors' is corrupt or truncated"):
        read_scene_file(bad)


@pytest.mark.parametrize("case", ["missing tensor", "mis-shaped tensor"])
def test_a_lazy_read_checks_the_field_on_first_use(tmp_path, case):
    """``lazy_field=True``: the same views, digest and background as a full read, the field decoded (bit for bit
    the same) only when used; a bad field is the same error then."""
    good = write(tmp_path / "good.n2r")
    eager, lazy = read_scene_file(good), read_scene_file(good, lazy_field=True)
    assert "field" not in vars(lazy), "a lazy read decoded the field"
    assert (lazy.field_digest, lazy.background, len(lazy.views)) == \
        (eager.field_digest, eager.background, len(eager.views))
    assert lazy.background == eager.field.background, "the file's background is not its field's"
    for name, tensor in eager.field.tensors().items():
        assert torch.equal(tensor, lazy.field.tensors()[name]), f"tensor {name!r} differs when decoded lazily"
    make, message = BAD_FILES[case]
    bad = tmp_path / "bad.n2r"
    make(good, bad)
    scene = read_scene_file(bad, lazy_field=True)
    with pytest.raises(SceneFileError, match=message):
        scene.field  # noqa: B018


def test_the_field_digest_names_the_stored_member(tmp_path):
    """Another field gives another digest, the same field written twice the same one (no inflating needed)."""
    field = random_field()
    first, again = write(tmp_path / "a.n2r", field), write(tmp_path / "b.n2r", field)
    other = write(tmp_path / "c.n2r", random_field(seed=1))
    digests = [read_scene_file(p, lazy_field=True).field_digest for p in (first, again, other)]
    assert digests[0] == digests[1] != digests[2], f"digests {digests}"


@pytest.mark.parametrize("edit", [
    lambda data: data["field"].__setitem__("density_shift", data["field"]["density_shift"] - 2.0),
    lambda data: data["field"].__setitem__("background", [0.25, 0.5, 0.75]),
    lambda data: data["normalization"].__setitem__("radius", data["normalization"]["radius"] * 2),
    lambda data: data["normalization"].__setitem__("shell", 1.0),
], ids=["density shift", "background", "radius", "shell"])
def test_the_field_digest_follows_the_field_settings_that_change_pixels(tmp_path, edit):
    """The same tensors with another density shift, background or normalization render other pixels, so the
    digest (and every content hash and render-cache key built on it) must differ."""
    path = write(tmp_path / "a.n2r", random_field())
    copied = rewrite(path, tmp_path / "b.n2r", edit_json=lambda data: None)  # the members stored as the edit's
    edited = rewrite(path, tmp_path / "c.n2r", edit_json=edit)
    same, other = (read_scene_file(p, lazy_field=True).field_digest for p in (copied, edited))
    assert same != other, "a field setting that changes pixels left the digest as it was"
    assert read_scene_file(rewrite(path, tmp_path / "d.n2r", edit_json=lambda data: None)).field_digest == same, \
        "the same file written twice has two digests"


def test_photos_in_subfolders_with_the_same_name_keep_their_own_copy(tmp_path):
    views = [type(v)(v.index, name, v.camera, v.c2w, v.split, v.image)
             for v, name in zip(tiny_views(3), ["left/img 1.png", "right/img 1.png", "img_1"])]
    path = write(tmp_path / "s.n2r", views=views)
    assert [n for n in zipfile.ZipFile(path).namelist() if n.startswith("images/")] == \
        ["images/img_1.jpg", "images/img_1_1.jpg", "images/img_1_2.jpg"]
    for saved, loaded in zip(views, read_scene_file(path).views):
        assert loaded.name == saved.name and np.abs(saved.image.astype(int) - loaded.image).mean() < 2.0, \
            f"frame {saved.name!r} got another frame's photo"


def test_frames_naming_one_photo_share_it_decoded_once(tmp_path, monkeypatch):
    """Many frames may name the same ``images/`` member (40 frames of one 4096² JPEG took 2.27 GB): it is decoded
    once, its array shared, and the memory check counts it once."""
    import pytest_n2r.scene.file as scene_file

    def same_photo(data):
        for frame in data["frames"]:
            frame["image"] = data["frames"][0]["image"]

    bad = rewrite(write(tmp_path / "good.n2r"), tmp_path / "same.n2r", edit_json=same_photo)
    decoded = []
    decode = scene_file._decode_jpeg
    monkeypatch.setattr(scene_file, "_decode_jpeg", lambda *a: decoded.append(a[1]) or decode(*a))
    checked = []
    monkeypatch.setattr(scene_file, "check_memory", lambda needed, source, what: checked.append(needed))
    scene = read_scene_file(bad)
    assert decoded == ["images/frame_000.jpg"]
    assert checked == [20 * 16 * 3], "the photos' memory check counts a photo once, however many frames name it"
    assert all(v.image is scene.views[0].image for v in scene.views)
    assert read_scene_file(bad, images=False).views[0].image is None


def test_an_allocator_failure_while_decoding_the_field_names_the_file(tmp_path, monkeypatch):
    from pytest_n2r.field.grid import SceneField

    def fail(*args):
        raise RuntimeError("[enforce fail at alloc_cpu.cpp:127] DefaultCPUAllocator: can't allocate memory")

    path = write(tmp_path / "scene.n2r")
    monkeypatch.setattr(SceneField, "from_tensors", fail)
    with pytest.raises(SceneFileError, match=r"scene\.n2r: field\.safetensors could not be decoded \(RuntimeError: "
                                             r".*can't allocate memory\); the field declared in scene\.json does not"):
        read_scene_file(path)


def test_a_splat_zip_needing_version_9_1_is_a_scene_file_error(tmp_path):
    from pytest_n2r.scene.splat_file import is_splat_file, read_splat_file

    path = write(tmp_path / "scene.n2r")
    data = bytearray(path.read_bytes())
    at = data.index(b"PK\x01\x02")
    data[at + 6:at + 8] = (91).to_bytes(2, "little")
    path.write_bytes(bytes(data))
    assert not is_splat_file(path)
    with pytest.raises(SceneFileError, match=r"scene\.n2r: not a zip archive this reader can open \(zip file "
                                             r"version 9\.1\)"):
        read_splat_file(path)


def test_a_member_compressed_by_a_method_zipfile_lacks_is_a_scene_file_error(tmp_path):
    """zipfile raises a bare NotImplementedError for a compression method it has no codec for."""
    import zipfile

    from pytest_n2r.errors import SceneFileError
    from pytest_n2r.scene.archive import read_member

    path = tmp_path / "method99.n2r"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("scene.json", "{}")
    data = bytearray(path.read_bytes())
    for signature, offset in ((b"PK\x01\x02", 10), (b"PK\x03\x04", 8)):  # central and local headers' method
        at = data.find(signature)
        data[at + offset:at + offset + 2] = (99).to_bytes(2, "little")
    path.write_bytes(bytes(data))
    with zipfile.ZipFile(path) as archive, pytest.raises(SceneFileError, match="'scene.json' is stored in a way this "
                                                                               "reader cannot open"):
        read_member(archive, "scene.json", str(path), 1000, "a test")


def test_reading_a_splat_scene_file_imports_no_torch():
    """The memory guard once imported pytest_n2r.fit for the free memory, and with it torch: 1.1 s more to load a
    splat scene, in every process and xdist worker."""
    import subprocess
    import sys

    code = ("import sys; import pytest_n2r.scene.loading, pytest_n2r.scene.splat_file, pytest_n2r.scene.splat_scene, "
            "pytest_n2r.scene.memory_guard; print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "False", "reading a splat scene file imported torch"


def test_each_frame_of_a_scene_file_comes_back_with_its_own_camera(tmp_path):
    """Frames of two cameras: each is read back with its own intrinsics, not the first camera's."""
    other = Camera(20, 16, 21.0, 19.0, 9.0, 8.0)
    views = [v if v.index % 2 == 0 else dataclasses.replace(v, camera=other) for v in tiny_views()]
    loaded = read_scene_file(write(tmp_path / "s.n2r", views=views))
    assert [v.camera for v in loaded.views] == [v.camera for v in views], [v.camera for v in loaded.views]
