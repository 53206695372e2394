"""Structure from motion on a folder of synthetic renders, and its input errors."""

from __future__ import annotations

import re
import time

import cv2
import numpy as np
import pytest
from PIL import Image

from pytest_n2r.data import ingest
from pytest_n2r.data.sfm import MIN_KEPT_SHARE, partial_registration, run_sfm
from pytest_n2r.errors import IngestError, InvalidType
from pytest_n2r.geometry import Camera, apply_similarity_to_pose, rotation_angle_deg, umeyama

from .synthetic import make_capture


def _errors(views, truth_by_name):
    src = np.array([v.c2w[:3, 3] for v in views])
    dst = np.array([truth_by_name[v.name][:3, 3] for v in views])
    s, R, t = umeyama(src, dst)
    rot = [rotation_angle_deg(apply_similarity_to_pose(v.c2w, s, R, t)[:3, :3], truth_by_name[v.name][:3, :3])
           for v in views]
    spread = np.sqrt(np.mean(np.sum((dst - dst.mean(0)) ** 2, axis=1)))
    centre = np.linalg.norm(src * s @ R.T + t - dst, axis=1) / spread
    return max(rot), centre.max()


@pytest.mark.slow
@pytest.mark.parametrize("matcher", ["exhaustive", "sequential"])
def test_sfm_recovers_the_rendered_poses(tmp_path, matcher):
    cap = make_capture(tmp_path, n=10, camera=Camera(320, 240, 280.0, 280.0, 159.5, 119.5))
    noise = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    cv2.imwrite(str(cap.images_dir / "zz_noise.png"), noise)  # cannot register
    start = time.perf_counter()
    result = ingest(cap.images_dir, matcher=matcher, downscale=0.5)
    took = time.perf_counter() - start
    assert took < 30, f"SfM of 11 small images took {took:.1f} s"
    assert [v.name for v in result.views] == cap.names, f"registered: {[v.name for v in result.views]}"
    reason = "not registered by structure from motion (too few features matched with the other photos)"
    assert result.skipped == [("zz_noise.png", reason)]
    assert result.report["warnings"] == [], "10 of 11 photos kept (91 %) is no partial reconstruction"
    assert result.report["matcher"] == matcher and result.views[0].image.shape == (120, 160, 3)
    rot, centre = _errors(result.views, dict(zip(cap.names, cap.c2ws)))
    assert rot < 0.5 and centre < 0.01, f"after similarity alignment: rotation {rot:.3f} deg, centre {centre:.2%}"
    assert result.views[0].camera.fx == pytest.approx(140.0, rel=0.02)  # 280 px at half size
    assert result.reference_length > 0 and np.all(result.bounds[0] < result.bounds[1])


def _folder_of(tmp_path, sizes):
    tmp_path.mkdir(exist_ok=True)
    for k, (w, h) in enumerate(sizes):
        Image.fromarray(np.full((h, w, 3), 100 + k, np.uint8)).save(tmp_path / f"{k}.png")  # each its own
    return tmp_path



@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:structure from motion on .* only 8 of the 10")  # sequential's, each run
@pytest.mark.parametrize("matcher", ["exhaustive", "sequential"])
def test_the_same_photos_give_the_same_reconstruction_on_several_threads(tmp_path, matcher):
    """Extraction's threads numbered the photos in the order they finished and each thread's RANSAC drew from a
    random seed: every run of ``n2r poses`` on the same photos gave other poses (camera centres 0.1 units apart in a
    scene 10 across), so every fit of them another scene."""
    cap = make_capture(tmp_path, n=10)
    runs = [run_sfm(cap.images_dir, matcher=matcher, num_threads=2) for _ in range(3)]
    first = {f.name: f.c2w for f in runs[0].frames}
    for again in runs[1:]:
        assert {f.name: f.c2w.tolist() for f in again.frames} == {k: v.tolist() for k, v in first.items()}, \
            "the same photos and seed gave another reconstruction"
        assert np.array_equal(again.points, runs[0].points), "the same photos and seed gave other points"

@pytest.mark.slow
def test_a_phone_capture_mixing_portrait_and_landscape_gets_one_camera_per_orientation(tmp_path):
    """Every third photo taken in portrait (the phone rolled 90°: viewed upright, the same pose with width and
    height swapped), half of those stored as phones store them (the sensor's landscape pixels + EXIF orientation
    6), JPEG: all register, each with its upright camera."""
    from pytest_n2r.demo.phone_capture import ROTATE_90_CW

    from .synthetic import orbit_poses, render, texture

    landscape = Camera(320, 240, 280.0, 280.0, 159.5, 119.5)
    portrait = Camera(240, 320, 280.0, 280.0, 119.5, 159.5)
    textures = [texture(k) for k in range(3)]
    folder = tmp_path / "photos"
    folder.mkdir()
    truth = {}
    for k, c2w in enumerate(orbit_poses(10)):
        turned = k % 3 == 2
        camera, pose = (portrait if turned else landscape), c2w
        rgb, _ = render(camera, pose, textures)
        exif = Image.Exif()
        if turned and k % 2 == 0:
            exif[0x0112] = ROTATE_90_CW
            rgb = np.rot90(rgb, k=1)
        name = f"IMG_{k:04d}.jpg"
        Image.fromarray(np.ascontiguousarray(rgb)).save(folder / name, quality=92, exif=exif)
        truth[name] = (pose, camera)
    result = ingest(folder, matcher="exhaustive")
    assert sorted(v.name for v in result.views) == sorted(truth), f"not registered: {result.skipped}"
    for v in result.views:
        assert (v.camera.width, v.camera.height) == (truth[v.name][1].width, truth[v.name][1].height), v.name
        assert v.image.shape[:2] == (v.camera.height, v.camera.width)
        assert v.camera.fx == pytest.approx(280.0, rel=0.03), (v.name, v.camera)
    cameras = {(c["width"], c["height"]): c for c in result.report["cameras"]}
    assert cameras[320, 240]["photos"] == 7 and cameras[240, 320]["photos"] == 3
    assert cameras[240, 320]["registered"] == 3
    rot, centre = _errors(result.views, {n: p for n, (p, _) in truth.items()})
    assert rot < 0.5 and centre < 0.01, f"after similarity alignment: rotation {rot:.3f} deg, centre {centre:.2%}"


@pytest.mark.slow
def test_a_photo_upside_down_against_the_others_is_skipped_unless_the_camera_rolls(tmp_path):
    """One photo of ten taken with the camera turned half a turn about its viewing direction (the phone held upside
    down): structure from motion registers it, rightly; against the others it is upside down, which on a capture
    held upright means a half-turn error (symmetric structure), so it is skipped, and kept with ``upright=False``."""
    cap = make_capture(tmp_path, n=10, camera=Camera(320, 240, 280.0, 280.0, 159.5, 119.5), upside_down=(4,))
    truth = dict(zip(cap.names, cap.c2ws))
    upright = run_sfm(cap.images_dir, matcher="exhaustive")
    assert [f.name for f in upright.frames] == [n for n in cap.names if n != "view_004.png"], upright.skipped
    [(name, reason)] = upright.skipped
    assert name == "view_004.png" and reason.startswith("registered upside down against the other photos (1"), reason
    record = upright.report["upright"]
    assert list(record["upside_down"]) == ["view_004.png"] and record["upside_down"]["view_004.png"] > 150, record
    assert record["photos"] == 10 and record["largest_upright_deg"] < 30 and record["dropped"], record
    assert upright.report["cameras"] == [{"width": 320, "height": 240, "photos": 10, "registered": 9}]

    rolling = run_sfm(cap.images_dir, matcher="exhaustive", upright=False)
    assert [f.name for f in rolling.frames] == cap.names and rolling.skipped == []
    kept = rolling.report["upright"]  # structure from motion runs on several threads: angles move a little
    assert kept["upside_down"].keys() == record["upside_down"].keys() and not kept["dropped"], kept
    rot, centre = _errors(rolling.frames, truth)
    assert rot < 0.5 and centre < 0.01, f"the turned photo's pose is right: rotation {rot:.3f} deg, centre {centre:.2%}"


@pytest.mark.slow
def test_more_than_a_quarter_upside_down_refuses_the_reconstruction(tmp_path):
    cap = make_capture(tmp_path, n=10, camera=Camera(320, 240, 280.0, 280.0, 159.5, 119.5), upside_down=(1, 4, 7))
    with pytest.raises(IngestError, match=r"registered 3 of 10 photos upside down against the others.*--any-roll"):
        run_sfm(cap.images_dir, matcher="exhaustive")
    assert len(run_sfm(cap.images_dir, matcher="exhaustive", upright=False).frames) == 10
    with pytest.raises(InvalidType, match=r"upright='no' must be True .* or False"):
        run_sfm(cap.images_dir, upright="no")


def test_too_few_readable_images(tmp_path):
    """The error names every unreadable file with its reason (the command line switches the warnings off)."""
    folder = _folder_of(tmp_path / "imgs", [(64, 48), (64, 48)])
    (folder / "2.png").write_bytes(b"broken")
    (folder / "3.png").write_bytes(b"")
    with pytest.warns(UserWarning), pytest.raises(IngestError) as error:
        run_sfm(folder)
    assert re.fullmatch(r"images folder '.*imgs': only 2 of 4 images are readable; structure from motion needs at "
                        r"least 3\. Unreadable: image file '.*2\.png' cannot be decoded as an image \(corrupt or not "
                        r"an image\); image file '.*3\.png' is empty \(0 bytes: .*\)", str(error.value)), error.value


def test_too_few_images_all_readable_says_so_and_names_the_subfolder_that_holds_more(tmp_path):
    """Two photos and ten more in a subfolder: "only 2 of 2 images are readable" blamed the photos, and the subfolder
    (not read) went unmentioned."""
    folder = _folder_of(tmp_path / "imgs", [(64, 48), (64, 48)])
    _folder_of(folder / "more", [(64, 48)] * 10)
    with pytest.raises(IngestError) as error:
        run_sfm(folder)
    message = str(error.value)
    assert "readable" not in message, message
    assert re.fullmatch(r"images folder '.*imgs' holds only 2 images \(0\.png, 1\.png\); structure from motion needs "
                        r"at least 3; its subfolder more holds 10 images, not read \(only the photos directly in the "
                        r"folder are\): put the capture's photos in one folder", message), message


def test_a_reconstruction_of_part_of_the_photos_is_warned_of():
    """The share is of the readable photos kept; below 90 % the warning names both counts and how to check."""
    text = partial_registration(31, 48)
    for expected in ("only 31 of the 48 readable photos registered and were kept (65 %, under 90 %)",
                     "n2r poses SOURCE --compare OTHER", "n2r render SCENE --view NAME"):
        assert expected in text, text
    assert partial_registration(48, 48) == partial_registration(44, 48) == partial_registration(0, 0) == ""
    assert MIN_KEPT_SHARE == 0.9


@pytest.mark.slow
def test_structure_from_motion_warns_when_it_keeps_part_of_the_photos_and_of_photos_in_subfolders(tmp_path):
    cap = make_capture(tmp_path, n=10, camera=Camera(320, 240, 280.0, 280.0, 159.5, 119.5))
    rng = np.random.default_rng(0)
    for k in range(3):  # photos of something else: they cannot register
        cv2.imwrite(str(cap.images_dir / f"zz_noise_{k}.png"), rng.integers(0, 256, (240, 320, 3), dtype=np.uint8))
    _folder_of(cap.images_dir / "older", [(64, 48)] * 2)
    with pytest.warns(UserWarning) as warned:
        poses = run_sfm(cap.images_dir, matcher="exhaustive", max_size=320)
    kept = len(poses.frames)
    assert kept == 10, poses.skipped
    notes = poses.report["warnings"]
    assert len(notes) == 2 and notes[0].startswith("only 10 of the 13 readable photos registered and were kept "
                                                   "(77 %, under 90 %)"), notes
    assert notes[1] == ("its subfolder older holds 2 images, not read (only the photos directly in the folder are): "
                        "put the capture's photos in one folder"), notes
    assert [str(w.message).split(": ", 1)[1] for w in warned if "structure from motion on" in str(w.message)] == notes


def test_given_files_are_the_only_photos_read(tmp_path):
    """A video's frames share their folder with whatever else is there: only the files given are photos of it."""
    folder = _folder_of(tmp_path / "imgs", [(64, 48), (64, 48)])
    (folder / "2.png").write_bytes(b"broken")
    (folder / "other.png").write_bytes(b"someone else's")
    given = [folder / f"{k}.png" for k in range(3)]
    with pytest.warns(UserWarning, match=r"2\.png") as warned, \
            pytest.raises(IngestError, match="only 2 of 3 images are readable"):
        run_sfm(folder, files=given)
    assert not [w for w in warned if "other.png" in str(w.message)], "a file that was not given was read"


@pytest.mark.parametrize(("kwargs", "match"),
                         [({"matcher": "vocab"}, "matcher='vocab'"), ({"max_size": 10}, "max_size=10")])
def test_bad_settings(tmp_path, kwargs, match):
    with pytest.raises(IngestError, match=match):
        run_sfm(_folder_of(tmp_path / "imgs", [(64, 48)] * 3), **kwargs)


@pytest.mark.slow
def test_featureless_images_register_nothing(tmp_path):
    folder = _folder_of(tmp_path / "imgs", [(64, 48)] * 3)
    with pytest.raises(IngestError, match="registered"):
        run_sfm(folder)


def test_pycolmap_failures_become_ingest_errors_naming_the_stage(tmp_path, monkeypatch):
    import pycolmap

    def broken(*args, **kwargs):
        raise RuntimeError("[matching.cc:1] Check failed: out of memory")

    monkeypatch.setattr(pycolmap, "match_exhaustive", broken)
    level = pycolmap.logging.minloglevel
    folder = _folder_of(tmp_path / "imgs", [(64, 48)] * 3)
    with pytest.raises(IngestError, match=r"imgs' failed during matching: .*out of memory"):
        run_sfm(folder)
    assert pycolmap.logging.minloglevel == level, "COLMAP's log level was not restored"


@pytest.mark.slow
def test_copies_and_links_of_a_photo_are_skipped_naming_the_original(tmp_path):
    """The same pixels twice (``IMG_0001 (1).JPG``, a link to a photo in the same folder) were both registered: one
    copy could be held out while its twin trained, its PSNR scoring a copy of a training photo."""
    import os

    cap = make_capture(tmp_path, n=8, camera=Camera(320, 240, 280.0, 280.0, 159.5, 119.5))
    images = cap.images_dir
    (images / "view_001 (1).png").write_bytes((images / "view_001.png").read_bytes())  # sorts before its original
    os.symlink("view_002.png", images / "view_002_link.png")
    rgb = np.asarray(Image.open(images / "view_003.png").convert("RGB"))
    rgba = np.dstack([rgb, np.full((240, 320), 255, np.uint8)])
    rgba[0, 0, 3] = 0  # one transparent pixel: warned of in the report, which n2r poses and n2r fit print
    Image.fromarray(rgba, "RGBA").save(images / "view_003.png")
    with pytest.warns(UserWarning, match=r"view_003\.png' has transparent pixels"):
        poses = run_sfm(images, matcher="exhaustive", max_size=320)
    assert [f.name for f in poses.frames] == [f"view_{k:03d}.png" for k in range(8)], poses.skipped
    assert poses.skipped == [("view_001 (1).png", "the same pixels as view_001.png (a copy or a link to it)"),
                             ("view_002_link.png", "the same pixels as view_002.png (a copy or a link to it)")]
    assert poses.report["images"] == 10 and poses.report["cameras"][0]["photos"] == 8
    note = (f"image file {str(images / 'view_003.png')!r} has transparent pixels: its alpha is dropped and the colour "
            "stored under them is read (a cut-out's removed background may show)")
    assert [text for text in poses.report["warnings"] if "transparent" in text] == [note]


def test_too_few_different_photos_counts_the_copies_apart_from_the_unreadable(tmp_path):
    folder = _folder_of(tmp_path / "imgs", [(64, 48), (64, 48)])
    (folder / "0 copy.png").write_bytes((folder / "0.png").read_bytes())
    (folder / "1 copy.png").write_bytes((folder / "1.png").read_bytes())
    with pytest.raises(IngestError) as error:
        run_sfm(folder)
    assert re.fullmatch(r"images folder '.*imgs': only 2 of 4 images are different; structure from motion needs at "
                        r"least 3\. Copies: 0 copy\.png has the same pixels as 0\.png \(a copy or a link to it\); "
                        r"1 copy\.png has the same pixels as 1\.png \(a copy or a link to it\)", str(error.value)), \
        error.value



def test_every_copy_names_the_photo_kept_even_when_it_is_read_last(tmp_path):
    """``IMG_1 (1).jpg`` is read first and kept until ``IMG_1.jpg``, read last, takes its place: ``IMG_1 (2).jpg``
    was said to have the pixels of ``IMG_1 (1).jpg``, itself skipped as a copy."""
    folder = _folder_of(tmp_path / "imgs", [(64, 48)])
    Image.fromarray(np.full((48, 64, 3), 50, np.uint8)).save(folder / "IMG_1.jpg")
    for copy in ("IMG_1 (1).jpg", "IMG_1 (2).jpg"):
        (folder / copy).write_bytes((folder / "IMG_1.jpg").read_bytes())
    with pytest.raises(IngestError) as error:
        run_sfm(folder)
    copies = str(error.value).split(". Copies: ")[1].split("; ")
    assert copies == [f"IMG_1 ({k}).jpg has the same pixels as IMG_1.jpg (a copy or a link to it)" for k in (2, 1)], \
        error.value


def test_photos_alike_but_in_the_pixels_between_those_sampled_are_not_copies(tmp_path, monkeypatch):
    """Photos are told apart by a sample of their pixels first: two that differ in one pixel outside it are both
    kept (compared in all their pixels, one photo read again for it), and a copy of either is found by its bytes."""
    from pytest_n2r.data import sfm

    folder = tmp_path / "imgs"
    folder.mkdir()
    image = np.full((48, 64, 3), 90, np.uint8)
    Image.fromarray(image).save(folder / "a.png")
    image[1, 1] = 91  # not on the sample's every 7th row and column
    Image.fromarray(image).save(folder / "b.png")
    for name in ("a", "b"):
        (folder / f"{name} copy.png").write_bytes((folder / f"{name}.png").read_bytes())  # read before its original
    read_again, read = [], sfm.read_image

    def counted(path):
        read_again.append(path.name)
        return read(path)

    monkeypatch.setattr(sfm, "read_image", counted)
    with pytest.raises(IngestError, match=r"only 2 of 4 images are different; .*Copies: a copy\.png has the same "
                                          r"pixels as a\.png \(a copy or a link to it\); b copy\.png has the same "
                                          r"pixels as b\.png "):
        run_sfm(folder)
    assert read_again == ["a.png"]  # to compare "b copy.png" with it; "a.png" and "b.png" have their copies' bytes


@pytest.mark.slow
def test_photos_too_small_to_register_say_their_size(tmp_path):
    """Three 32x24 photos: "registered no images (too little overlap or texture?)" did not say they were tiny."""
    folder = tmp_path / "tiny"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k in range(3):
        Image.fromarray(rng.integers(0, 256, (24, 32, 3), np.uint8)).save(folder / f"{k}.png")
    with pytest.raises(IngestError, match=r"registered (no|only \d) images.* the largest photo is 32x24 pixels, too "
                                          "small to find enough features in"):
        run_sfm(folder)
