"""``n2r poses``: the summary it prints and the transforms.json it writes."""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest

from pytest_n2r.cli.main import main
from pytest_n2r.data import read_transforms_json

from .synthetic import make_capture, write_transforms


def test_poses_prints_a_summary_and_writes_transforms_json(corner, tmp_path, capsys):
    (corner.images_dir / corner.names[5]).unlink()
    src = write_transforms(corner)
    out = tmp_path / "out" / "poses.json"
    assert main(["poses", str(src), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    for expected in (
        "6 found, 5 registered, 1 skipped", f"images/{corner.names[5]}", "160x120 fx=150.00 fy=150.00 cx=79.50",
        "reference", "bounds", "time", f"wrote       {out} (5 frames)",
    ):
        assert expected in text, f"{expected!r} missing from the summary:\n{text}"
    written = read_transforms_json(out)
    assert [f.path.name for f in written.frames] == corner.names[:5]
    for frame, c2w in zip(written.frames, corner.c2ws):
        np.testing.assert_allclose(frame.c2w, c2w, atol=1e-12)
        assert frame.camera == corner.camera
    meta = json.loads(out.read_text())
    ref = float(text.split("reference   ")[1].split()[0])
    assert abs(meta["n2r"]["reference_length"] - ref) <= 1e-3 * ref


def test_poses_output_keeps_the_sources_split(corner, tmp_path):
    src = write_transforms(corner, val_filenames=[f"./images/{corner.names[3]}"])
    out = tmp_path / "out" / "poses.json"
    assert main(["poses", str(src), "-o", str(out)]) == 0
    meta = json.loads(out.read_text())
    paths = [f["file_path"] for f in meta["frames"]]
    assert meta.get("val_filenames") == [paths[3]], f"n2r poses -o lost the split: {meta.get('val_filenames')}"
    assert meta.get("train_filenames") == paths[:3] + paths[4:]
    assert [f.name in read_transforms_json(out).heldout for f in read_transforms_json(out).frames] == \
        [k == 3 for k in range(6)], "the written split reads back as other views"


def test_poses_error_names_the_source(tmp_path, capsys):
    assert main(["poses", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err
    assert "n2r poses: error:" in err and "missing" in err and "does not exist" in err


@pytest.mark.slow
@pytest.mark.parametrize(("flags", "skipped"), [([], 1), (["--any-roll"], 0)])
def test_poses_says_whether_the_photos_agree_on_up(tmp_path, capsys, flags, skipped):
    cap = make_capture(tmp_path, n=10, upside_down=(4,))
    assert main(["poses", str(cap.images_dir), "--matcher", "exhaustive", *flags]) == 0
    text = capsys.readouterr().out
    assert f"10 found, {10 - skipped} registered, {skipped} skipped" in text, text
    assert ("skipped   view_004.png: registered upside down against the other photos" in text) == bool(skipped)
    assert "upright     1 of 10 photos upside down against the others (view_004.png 1" in text, text


@pytest.mark.slow
def test_fit_keeps_a_camera_that_rolls_with_any_roll(tmp_path, capsys):
    cap = make_capture(tmp_path, n=10, upside_down=(4,))
    out = tmp_path / "corner.n2r"
    assert main(["fit", str(cap.images_dir), "-o", str(out), "--any-roll", "--downscale", "1", "--max-steps", "5",
                 "--config", "resolutions=16,24", "--config", "stage_fractions=0.5", "--appearance", "off"]) == 0
    text = capsys.readouterr().err
    assert "8 training views, 2 held out" in text, f"the turned photo was not kept:\n{text}"
    assert "upright     1 of 10 photos upside down against the others" in text and "skipped" not in text, text


def _with_missing_photos(corner, count: int = 12):
    """The corner's transforms.json listing ``count`` more frames whose photos are missing (as the fox's lists 17)."""
    src = write_transforms(corner)
    meta = json.loads(src.read_text())
    pose = meta["frames"][0]["transform_matrix"]
    meta["frames"] += [{"file_path": f"images/gone_{k:02d}.png", "transform_matrix": pose} for k in range(count)]
    src.write_text(json.dumps(meta))
    return src, [f"images/gone_{k:02d}.png" for k in range(count)]


def test_poses_lists_every_skipped_photo_and_keeps_them_in_its_output(corner, tmp_path, capsys):
    """The summary showed the first ten and "... and 9 more" (an unrelated photo among those hidden), and the list was
    kept nowhere: every one is printed now, and written in the output's n2r block."""
    src, missing = _with_missing_photos(corner)
    out = tmp_path / "poses.json"
    assert main(["poses", str(src), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "18 found, 6 registered, 12 skipped" in text, text
    for name in missing:
        assert f"  skipped   {name}: image file " in text, f"{name} is not in the summary:\n{text}"
    assert "more" not in text, text
    block = json.loads(out.read_text())["n2r"]
    assert block["images"] == 18 and [r["file"] for r in block["skipped"]] == missing, block
    assert all("does not exist" in r["reason"] for r in block["skipped"]) and block["warnings"] == [], block
    assert len(read_transforms_json(out).frames) == 6, "the n2r block changed what a transforms.json reader sees"


def test_poses_prints_and_keeps_the_warnings_of_ingestion_and_where_a_videos_frames_went(corner, tmp_path, capsys,
                                                                                        monkeypatch):
    """A reconstruction of part of the photos exited 0 without a word: its warning goes to stderr and into the
    output; a video's frames folder is named on a line of its own."""
    ingestion = importlib.import_module("pytest_n2r.data.ingest")  # the module: the package's `ingest` is its function

    real = ingestion.load_poses
    note = "only 31 of the 48 readable photos registered and were kept"

    def partial(*args, **kwargs):
        poses = real(*args, **kwargs)
        poses.report.update(warnings=[note],
                            video="walk.mp4", frames_dir="walk_frames", video_frames=120)
        return poses

    monkeypatch.setattr(ingestion, "load_poses", partial)
    out = tmp_path / "poses.json"
    assert main(["poses", str(write_transforms(corner)), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert f"n2r poses: warning: {note}" in captured.err, captured
    assert "frames      120 frames of walk.mp4 extracted to walk_frames" in captured.out, captured.out
    assert json.loads(out.read_text())["n2r"]["warnings"] == [note]


def test_fit_shares_the_frames_dir_option_of_poses_and_hands_it_to_ingestion(tmp_path, monkeypatch, capsys):
    """The video's frames-folder error told n2r fit users to pass --frames-dir, which n2r fit did not have."""
    import pytest_n2r.data
    from pytest_n2r.cli.main import build_parser
    from pytest_n2r.errors import IngestError

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    helps = {name: next(a.help for a in sub.choices[name]._actions if "--frames-dir" in a.option_strings)
             for name in ("poses", "fit")}
    assert helps["poses"] == helps["fit"], helps
    seen = {}

    def stop(source, **kwargs):
        seen.update(kwargs)
        raise IngestError("stopped here")

    monkeypatch.setattr(pytest_n2r.data, "ingest", stop)
    video = tmp_path / "walk.mp4"
    video.write_bytes(b"not read")
    frames = tmp_path / "frames"
    assert main(["fit", str(video), "-o", str(tmp_path / "walk.n2r"), "--frames-dir", str(frames), "--force"]) == 2
    assert "stopped here" in capsys.readouterr().err
    assert (seen["frames_dir"], seen["force_frames_dir"]) == (frames, True), seen
    # --force given to replace the output alone must not write frames over files in the default frames folder
    assert main(["fit", str(video), "-o", str(tmp_path / "walk.n2r"), "--force"]) == 2
    assert (seen["frames_dir"], seen["force_frames_dir"]) == (None, False), seen


@pytest.mark.slow
def test_fit_keeps_every_skipped_photo_and_warning_in_its_report(corner, tmp_path, capsys, monkeypatch):
    ingestion = importlib.import_module("pytest_n2r.data.ingest")  # the module: the package's `ingest` is its function
    from pytest_n2r.scene import read_scene_file

    real = ingestion.load_poses

    def partial(*args, **kwargs):
        poses = real(*args, **kwargs)
        poses.report["warnings"] = ["only 6 of the 18 photos"]
        return poses

    monkeypatch.setattr(ingestion, "load_poses", partial)
    src, missing = _with_missing_photos(corner)
    out = tmp_path / "corner.n2r"
    assert main(["fit", str(src), "-o", str(out), "--downscale", "1", "--max-steps", "2", "--config",
                 "resolutions=16,24", "--config", "stage_fractions=0.5", "--appearance", "off", "--no-images"]) == 0
    err = capsys.readouterr().err
    assert all(f"  skipped   {name}: image file " in err for name in missing) and "more" not in err, err
    assert "n2r fit: warning: only 6 of the 18 photos" in err, err
    report = read_scene_file(out, images=False).report
    assert [r["file"] for r in report["skipped"]] == missing and "does not exist" in report["skipped"][0]["reason"]
    assert report["warnings"] == ["only 6 of the 18 photos"], report["warnings"]


def test_poses_compare_reads_the_other_source_as_the_first_any_roll_included(tmp_path, monkeypatch, capsys):
    import importlib

    ingest = importlib.import_module("pytest_n2r.data.ingest")  # the package re-exports a function of that name
    assert main(["demo", "export", "object", "-o", str(tmp_path / "cap"), "--size", "32x24"]) == 0
    calls, real = [], ingest.load_poses

    def recording(source, **kw):
        calls.append(kw)
        return real(source, **kw)

    monkeypatch.setattr(ingest, "load_poses", recording)
    source = str(tmp_path / "cap" / "transforms.json")
    assert main(["poses", source, "--compare", source, "--any-roll", "--max-size", "480"]) == 0, capsys.readouterr().err
    assert [(c.get("upright"), c["sfm_max_size"]) for c in calls] == [(False, 480), (False, 480)]


@pytest.mark.parametrize(("count", "more"), [(3, None), (4, "  ... and 1 more")])
def test_the_summary_lists_three_cameras_and_counts_the_rest(count, more):
    from pytest_n2r.cli.poses import format_summary
    from pytest_n2r.data.poses import PoseSet, SourceFrame
    from pytest_n2r.geometry import Camera

    cameras = [Camera(64, 48, 50.0 + k, 50.0, 31.5, 23.5) for k in range(count)]  # each frame a camera of its own
    frames = [SourceFrame(f"{k}.png", None, camera, np.eye(4)) for k, camera in enumerate(cameras)]
    lines = format_summary(PoseSet(frames=frames, points=np.zeros((1, 3))), np.zeros((2, 3)), 1.0, 0.1).splitlines()
    assert sum(line.startswith("  64x48 fx=") for line in lines) == 3, lines
    assert [line for line in lines if "more" in line] == ([more] if more else []), lines
