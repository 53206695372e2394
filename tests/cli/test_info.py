"""`n2r info`: strict JSON whatever the shift measured, --shift on a splat scene file says why it cannot, and a splat
scene file's summary is read as a fitted one's is."""

from __future__ import annotations

import json
import math
import zipfile

import pytest

import pytest_n2r.cli.info
from pytest_n2r.cli.main import main
from pytest_n2r.demo.fitted import packaged_path
from pytest_n2r.study.fidelity import FidelityReport

from ..splats.make_data import DATA, FILES


def _strict(text: str) -> dict:
    def refuse(name: str) -> float:
        raise AssertionError(f"`n2r info --json` printed {name}, which is not JSON")

    return json.loads(text, parse_constant=refuse)


def test_info_json_with_a_shift_of_undefined_scores_is_strict_json(monkeypatch, capsys):
    """A shift with no defined sample (no detector found anything, or no photo to compare with) has NaN means:
    printed as null, never as NaN, which no strict JSON reader reads."""
    undefined = FidelityReport("wall", "64", "photo", "", ({"view": "v0", "psnr": math.inf, "ssim": 1.0},), {})
    monkeypatch.setattr(pytest_n2r.cli.info, "_shift", lambda scene, size: undefined)
    assert main(["info", str(packaged_path("wall")), "--json", "--shift", "--size", "64"]) == 0
    shift = _strict(capsys.readouterr().out)["shift"]
    assert shift["psnr"] is None and shift["detectors"]["orb"]["repeatability"] is None, shift


@pytest.fixture(scope="module")
def splat_file(tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("splats") / "object.n2r"
    assert main(["import", str(DATA / FILES["object-sh0"][0]), "-o", str(out)]) == 0
    return out


def test_shift_on_a_splat_scene_file_is_an_error_not_ignored(splat_file, capsys):
    capsys.readouterr()
    assert main(["info", str(splat_file), "--shift"]) == 2, "--shift on a splat scene file was ignored"
    out, err = capsys.readouterr()
    assert (f"n2r info: error: --shift is not supported for {splat_file}: it is a splat scene file (n2r import packs "
            "the splats and their cameras, no photos), so it has no photos") in err
    assert not out, f"printed the summary as if --shift had been measured:\n{out}"
    assert main(["info", str(splat_file), "--json"]) == 0
    assert _strict(capsys.readouterr().out)["representation"] == "splats"


def test_the_report_lines_say_how_far_the_heldout_views_are_and_what_the_training_views_score():
    """A video's held-out frames between fitted ones: each row says its nearest fitted view, the summary the median
    and the least, and the training views' scores follow, so the held-out score can be read against them."""
    rows = [{"view": "f000", "psnr": 29.5, "ssim": 0.9, "nearest": "f001", "nearest_degrees": 1.4,
             "nearest_distance": 0.021},
            {"view": "f008", "psnr": 30.2, "ssim": 0.91, "nearest": "f007", "nearest_degrees": 4.6,
             "nearest_distance": 0.07}]
    report = {"heldout": rows, "psnr": 29.85, "ssim": 0.905, "train_psnr": 31.25, "train_ssim": 0.93,
              "nearest_fitted": {"degrees": {"median": 3.0, "min": 1.4}, "distance": {"median": 0.0456, "min": 0.021}},
              "train_scored": [{"view": f"f{i:03d}", "psnr": 31.25, "ssim": 0.93} for i in range(1, 9)]}
    lines = pytest_n2r.cli.info._report_lines(report)
    assert "held out    PSNR 29.85 dB, SSIM 0.9050 (mean of 2 views)" in lines, lines
    assert ("  nearest   fitted view 3.0° and 0.046 reference lengths away (median; least 1.4° and 0.021): how new "
            "the poses are") in lines, lines
    assert "  f000    29.50  0.9000    1.4°  0.021 ref. lengths  f001" in lines, lines
    assert ("training    PSNR 31.25 dB, SSIM 0.9300 (mean of 8 training views along the capture, scored as the "
            "held-out ones)") in lines, lines
    assert all(len(line) <= 120 for line in lines), lines


def test_a_report_from_before_the_gaps_and_training_scores_prints_as_before(capsys):
    """The shipped demo files' reports hold no ``nearest_fitted`` or ``train_psnr``: no line for them, no error."""
    assert main(["info", str(packaged_path("wall"))]) == 0
    text = capsys.readouterr().out
    assert "held out    PSNR" in text and "  view" in text, text
    assert "nearest" not in text and "training    " not in text, text


def test_the_report_lines_list_every_photo_the_fit_skipped_and_its_warnings():
    """The photos that did not register were printed once, ten of them, and kept nowhere."""
    skipped = [{"file": f"IMG_{i:04d}.JPG", "reason": "not registered by structure from motion"} for i in range(12)]
    report = {"skipped": skipped, "warnings": ["only 31 of the 48 readable photos registered and were kept"]}
    lines = pytest_n2r.cli.info._report_lines(report)
    assert [line for line in lines if line.startswith("  skipped")] == [
        f"  skipped   IMG_{i:04d}.JPG: not registered by structure from motion" for i in range(12)], lines
    assert "  warning   only 31 of the 48 readable photos registered and were kept" in lines, lines


def test_a_splat_scene_files_summary_is_lines_not_python_reprs(splat_file, capsys):
    """The summary printed the splats' and the import report's dicts and the bounds' nested list as Python wrote
    them (``{'count': 4000, ...}``)."""
    capsys.readouterr()
    assert main(["info", str(splat_file)]) == 0
    text = capsys.readouterr().out
    assert not any(mark in text for mark in ("{'", "[[", "':")), f"a Python repr in the summary:\n{text}"
    lines = text.splitlines()
    assert lines[0].startswith(f"scene       {splat_file} (") and lines[0].endswith(", 3-D Gaussian splats)"), lines
    assert "views       48: 42 train, 6 held out; no photos stored" in lines, lines
    assert "splats      4000 Gaussians, SH degree 0, background (0, 0, 0)" in lines, lines
    assert any(line.startswith("bounds      x -17.33 to 15.81, y ") for line in lines), lines
    assert any(line.startswith("  source    ") and "(sha256 " in line for line in lines), lines
    assert all(len(line) <= 120 for line in lines if not line.startswith(("  source", "  cameras"))), lines


def test_a_splat_scene_files_report_edited_by_hand_is_an_error_naming_the_file(splat_file, tmp_path, capsys):
    edited = tmp_path / "edited.n2r"
    with zipfile.ZipFile(splat_file) as old, zipfile.ZipFile(edited, "w") as new:
        for item in old.infolist():
            data = old.read(item)
            if item.filename == "scene.json":
                scene = json.loads(data)
                scene["report"]["import_s"] = "fast"
                data = json.dumps(scene).encode()
            new.writestr(item, data)
    capsys.readouterr()
    assert main(["info", str(edited)]) == 2
    err = capsys.readouterr().err
    assert f"{edited}: scene.json report 'source', 'source_sha256', 'cameras', 'from_field', 'imported_by' or " in err
    assert "ValueError: Unknown format code 'f'" in err and "n2r info --json prints it as stored" in err, err


def _cams(n):
    return [{"width": 64, "height": 48, "fx": 50.0, "fy": 50.0, "cx": 32.0, "cy": 24.0} for _ in range(n)]


@pytest.mark.parametrize(("n", "more"), [(3, None), (4, "  ... and 1 more cameras"), (6, "  ... and 3 more cameras")])
def test_the_camera_lines_show_three_and_count_the_rest(n, more):
    from pytest_n2r.cli.info import _camera_and_scale_lines

    lines = _camera_and_scale_lines({"cameras": _cams(n), "metres_per_unit": None, "reference_length": 1.0})
    assert sum(line.startswith("  camera ") for line in lines) == min(n, 3)
    assert [line for line in lines if "more cameras" in line] == ([more] if more else [])


def test_info_json_of_a_fitted_scene_counts_tensor_bytes_and_its_split(capsys):
    from pytest_n2r.demo.fitted import packaged_path
    from pytest_n2r.scene.file import read_scene_file

    path = packaged_path("wall")
    assert main(["info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    scene = read_scene_file(path, images=False)
    tensors = scene.field.tensors().values()
    assert info["field"]["tensor_bytes"] == sum(t.numel() * t.element_size() for t in tensors)
    splits = [v.split for v in scene.views]
    assert (info["train_views"], info["heldout_views"]) == (splits.count("train"), splits.count("heldout"))
    assert main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    assert f"{100 * info['field']['occupied_fraction']:.1f}% of cells occupied" in text, text


def test_info_of_an_exact_scene_counts_its_split_and_photos(capsys):
    from pytest_n2r.demo import ground_truth

    assert main(["info", "demo:wall", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    scene = ground_truth("wall")
    splits = [v.split for v in scene.views]
    assert (info["views"], info["train_views"], info["heldout_views"]) == (
        len(splits), splits.count("train"), splits.count("heldout"))
    assert info["photos_stored"] == sum(v.image is not None for v in scene.views)


def test_report_lines_of_a_report_with_gains_history_and_compile_time():
    from pytest_n2r.cli.info import _report_lines

    lines = "\n".join(_report_lines({
        "complete": True, "steps": 10, "train_seconds": 3.0, "compile_seconds": 0.2,
        "source": "cap", "appearance": {"a.png": [0.9, 1.0, 1.1], "b.png": [1.2, 1.0, 0.95]},
        "history": [{"seconds": 1, "step": 3, "psnr": 20.0, "ssim": 0.5}],
    }))
    assert "fit         complete: 10 steps, 3.0 s of training (and 0.2 s compiling its kernels)" in lines, lines
    assert "  source    cap (downscale 1)" in lines, lines
    assert "(2 photos, 0.900 to 1.200); renders use none" in lines, lines
    assert "after 1 s of training (step 3): PSNR 20.00 dB, SSIM 0.5000" in lines, lines


# poses.py / fit.py / study.py / demo.py: the smallest values documented as accepted -------------------------------
