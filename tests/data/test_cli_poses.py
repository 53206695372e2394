"""``n2r poses``: the summary it prints and the transforms.json it writes."""

from __future__ import annotations

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
        "reference", "bounds", "time", f"wrote       {out}",
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
