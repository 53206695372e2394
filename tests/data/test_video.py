"""Video files: sharpest frame per window, reuse of extracted frames, errors, and SfM on a video."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from pytest_n2r.data import ingest, source_kind
from pytest_n2r.data.video import default_frames_dir, extract_frames
from pytest_n2r.errors import IngestError
from pytest_n2r.geometry import Camera

from .synthetic import orbit_poses, render, texture


def _write_video(path, frames_rgb, fps=10):
    h, w = frames_rgb[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    assert writer.isOpened(), "OpenCV cannot write MJPG .avi here"
    for frame in frames_rgb:
        writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    writer.release()
    return path


@pytest.fixture(scope="module")
def corner_frames():
    cam = Camera(160, 120, 150.0, 150.0, 79.5, 59.5)
    textures = [texture(k) for k in range(3)]
    return [render(cam, c2w, textures)[0] for c2w in orbit_poses(12)]


def test_sharpest_frame_of_each_window_is_kept(tmp_path, corner_frames):
    blurred = [cv2.GaussianBlur(f, (0, 0), 3) for f in corner_frames]
    # windows of 3 frames: blurred, sharp, blurred -> the sharp middle one (index 1, 4, 7, 10) wins
    frames = [blurred[0], corner_frames[1], blurred[2], blurred[3], corner_frames[4], blurred[5],
              blurred[6], corner_frames[7], blurred[8], blurred[9], corner_frames[10], blurred[11]]
    video = _write_video(tmp_path / "walk.avi", frames)
    out = extract_frames(video, max_frames=4)
    assert [p.name for p in out] == ["frame_01.png", "frame_04.png", "frame_07.png", "frame_10.png"]
    assert out[0].parent == default_frames_dir(video) == tmp_path / "walk_frames"
    got = cv2.cvtColor(cv2.imread(str(out[1])), cv2.COLOR_BGR2RGB).astype(int)
    errors = [np.abs(got - f.astype(int)).mean() for f in frames]  # MJPG is lossy: nearest, not equal
    assert int(np.argmin(errors)) == 4, f"frame_04.png is closest to video frame {np.argmin(errors)}: {errors}"


def test_frames_are_reused_for_the_same_video_and_settings(tmp_path, corner_frames):
    video = _write_video(tmp_path / "v.avi", corner_frames)
    first = extract_frames(video, tmp_path / "f", max_frames=5)
    stamp = [p.stat().st_mtime_ns for p in first]
    again = extract_frames(video, tmp_path / "f", max_frames=5)
    assert again == first and [p.stat().st_mtime_ns for p in again] == stamp
    other = extract_frames(video, tmp_path / "f", max_frames=3)
    assert len(other) == 3 and len(list((tmp_path / "f").glob("frame_*.png"))) == 3
    assert json.loads((tmp_path / "f" / "frames.json").read_text())["max_frames"] == 3


def test_an_extraction_cut_short_is_redone_not_reused(tmp_path, corner_frames):
    """A frames.json left by an extraction interrupted after 3 of 5 frames (``complete`` false) is not taken as the
    extraction: the frames are extracted again, all 5."""
    video = _write_video(tmp_path / "v.avi", corner_frames)
    first = extract_frames(video, tmp_path / "f", max_frames=5)
    manifest = tmp_path / "f" / "frames.json"
    saved = json.loads(manifest.read_text())
    saved["frames"], saved["complete"] = saved["frames"][:3], False
    manifest.write_text(json.dumps(saved))
    again = extract_frames(video, tmp_path / "f", max_frames=5)
    assert again == first, f"after an interrupted extraction: {[p.name for p in again]}"
    assert json.loads(manifest.read_text())["complete"] is True


def test_more_windows_than_frames_keeps_every_frame(tmp_path, corner_frames):
    video = _write_video(tmp_path / "v.avi", corner_frames[:4])
    assert len(extract_frames(video, tmp_path / "f", max_frames=50)) == 4


def test_video_errors_name_the_file(tmp_path, corner_frames):
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"\x00" * 100)
    with pytest.raises(IngestError, match="broken.mp4"):
        extract_frames(bad)
    short = _write_video(tmp_path / "short.avi", corner_frames[:2])
    with pytest.raises(IngestError, match=r"short\.avi' has 2 decodable frames; at least 3"):
        extract_frames(short)
    with pytest.raises(IngestError, match="max_frames=1"):
        extract_frames(short, max_frames=1)


def test_unwritable_frames_folder(tmp_path, corner_frames):
    video = _write_video(tmp_path / "v.avi", corner_frames)
    (tmp_path / "a_file").write_text("")
    with pytest.raises(IngestError, match=r"cannot write video frames to .*a_file/f"):
        extract_frames(video, tmp_path / "a_file" / "f")


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_a_folder_of_other_files_is_refused_and_left_as_it_was(tmp_path, corner_frames):
    """nerfstudio names its processed images frame_00001.png: they were deleted as if they were our frames."""
    video = _write_video(tmp_path / "v.avi", corner_frames)
    mine = tmp_path / "photos"
    mine.mkdir()
    for name in ("frame_00001.png", "frame_01.png", "notes.txt"):
        (mine / name).write_bytes(name.encode())
    before = _snapshot(mine)
    with pytest.raises(IngestError, match=r"frames folder '.*photos' holds other files and no frames\.json") as error:
        extract_frames(video, mine, max_frames=4)
    # n2r fit has no option the message names but n2r poses has (it told n2r fit users to pass --frames-dir)
    assert "--frames-dir DIR (n2r poses, n2r fit; frames_dir= in Python)" in str(error.value), error.value
    assert _snapshot(mine) == before, "the user's files were changed"


def test_of_a_folder_of_ours_only_the_frames_its_manifest_lists_are_replaced(tmp_path, corner_frames):
    video = _write_video(tmp_path / "v.avi", corner_frames)
    extract_frames(video, tmp_path / "f", max_frames=5)
    (tmp_path / "f" / "frame_99.png").write_bytes(b"the user's")  # put there since, named like a frame
    again = extract_frames(video, tmp_path / "f", max_frames=3)
    left = sorted(p.name for p in (tmp_path / "f").iterdir())
    assert left == sorted([p.name for p in again] + ["frame_99.png", "frames.json"]), \
        f"after re-extracting, the folder holds {left}: earlier frames kept or the user's file deleted"
    assert (tmp_path / "f" / "frame_99.png").read_bytes() == b"the user's"


def test_force_writes_among_other_files_and_structure_from_motion_sees_the_frames_only(tmp_path, corner_frames,
                                                                                     monkeypatch):
    from pytest_n2r.data import PoseSet, load_poses, sfm

    video = _write_video(tmp_path / "v.avi", corner_frames)
    mine = tmp_path / "photos"
    mine.mkdir()
    (mine / "holiday.jpg").write_bytes(b"a photo")
    seen = {}

    def fake_sfm(images_dir, **kwargs):
        seen.update(kwargs, images_dir=images_dir)
        return PoseSet(frames=[], report={"time_s": {}})

    monkeypatch.setattr(sfm, "run_sfm", fake_sfm)
    with pytest.raises(IngestError, match="holds other files"):
        load_poses(video, frames_dir=mine, max_frames=4)
    load_poses(video, frames_dir=mine, max_frames=4, force_frames_dir=True)
    assert (mine / "holiday.jpg").read_bytes() == b"a photo"
    frames = sorted(p for p in mine.glob("frame_*.png"))
    assert seen.get("files") == frames and len(frames) == 4, \
        f"structure from motion was given {seen.get('files')}, not the video's 4 frames only"
    assert not [p for p in mine.iterdir() if p.name.startswith(".")], "a temporary file was left behind"
    assert json.loads((mine / "frames.json").read_text())["complete"] is True


def test_a_video_is_a_source_of_its_own_kind(tmp_path, corner_frames):
    video = _write_video(tmp_path / "v.avi", corner_frames)
    assert source_kind(video) == ("video", video)


@pytest.mark.slow
def test_sfm_on_a_video(tmp_path):
    cam = Camera(320, 240, 280.0, 280.0, 159.5, 119.5)
    textures = [texture(k) for k in range(3)]
    frames = [render(cam, c2w, textures)[0] for c2w in orbit_poses(24)]
    video = _write_video(tmp_path / "orbit.avi", frames)
    cap = ingest(video, max_frames=12, frames_dir=tmp_path / "frames", downscale=0.5)
    assert cap.report["kind"] == "video" and cap.report["matcher"] == "sequential"
    assert (cap.report["frames_dir"], cap.report["video_frames"]) == (str(tmp_path / "frames"), 12), cap.report
    assert len(cap.views) >= 10, f"only {len(cap.views)} of 12 video frames registered: {cap.skipped}"
    assert cap.views[0].image.shape == (120, 160, 3)
