"""`n2r info --shift` and benchmarks/fidelity.py: PSNR / SSIM beside the detectors' reality-to-field shift."""

from __future__ import annotations

import importlib.util
import json
import math
import sys

import pytest

from pytest_n2r.cli.main import main
from pytest_n2r.scene import save_scene

from ..conftest import REPO_ROOT


def test_info_shift_prints_psnr_and_each_detectors_shift(tiny_scene_file, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("N2R_CACHE_DIR", str(tmp_path / "cache"))
    assert main(["info", str(tiny_scene_file), "--shift", "--size", "64"]) == 0
    out = capsys.readouterr().out
    assert "reality-to-field shift: each detector on the stored photo vs on the render" in out
    assert "mean of 6 views" in out and "render vs reference   PSNR" in out
    for detector in ("orb", "sift", "akaze"):
        assert any(line.split()[:1] == [detector] for line in out.splitlines()), out
    header = next(line for line in out.splitlines() if line.split()[:1] == ["detector"])
    assert header.split()[-2:] == ["nearest", "photo"], f"no yardstick column: {header!r}"
    assert "nearest photo: the nearest other fitted photo (median " in out, out
    assert list((tmp_path / "cache" / "floors").glob("*.json")), "the floors are cached"

    assert main(["info", str(tiny_scene_file), "--shift", "--size", "64", "--json"]) == 0
    shift = json.loads(capsys.readouterr().out)["shift"]
    assert shift["reference"] == "photo" and len(shift["images"]) == 6
    assert set(shift["detectors"]) == {"orb", "sift", "akaze"}
    assert math.isfinite(shift["psnr"]) and 0 < shift["ssim"] <= 1
    assert set(shift["nearby"]) == {"orb", "sift", "akaze"}, shift["nearby"]
    assert all(v is None or 0 <= v <= 1 for v in shift["nearby"].values()), shift["nearby"]
    assert shift["nearby_degrees"] > 0, "the nearest other photo is the view itself"


def test_info_shift_without_photos_says_why(tiny_capture, tiny_fit, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("N2R_CACHE_DIR", str(tmp_path / "cache"))
    path = save_scene(tmp_path / "bare.n2r", tiny_fit.field, tiny_fit.config, tiny_capture, tiny_fit.report,
                      images=False)
    assert main(["info", str(path), "--shift"]) == 0
    assert "reality-to-field shift n/a: scene 'bare' stores no photos of its held-out views" in capsys.readouterr().out


@pytest.fixture(scope="module")
def fidelity_benchmark():
    spec = importlib.util.spec_from_file_location("fidelity_benchmark", REPO_ROOT / "benchmarks" / "fidelity.py")
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(REPO_ROOT / "benchmarks"))  # as when run: the script imports its folder's _scoring
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(REPO_ROOT / "benchmarks"))
    return module


def test_the_fidelity_benchmark_runs_on_a_fitted_demo_scene(fidelity_benchmark, tmp_path, capsys):
    out = tmp_path / "fidelity.json"
    assert fidelity_benchmark.main(["demo:wall-field", "--size", "96", "--views", "2", "--targets",
                                    "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| demo:wall-field | exact | 2 |" in text and "targets: held-out PSNR >= 28 dB" in text
    (report,) = json.loads(out.read_text())
    assert report["reference"] == "exact" and report["psnr"] > 20


def test_the_fidelity_ceiling_scores_the_reference_against_itself_degraded(fidelity_benchmark, tmp_path, capsys):
    out = tmp_path / "ceiling.json"
    assert fidelity_benchmark.main(["demo:wall-field", "--size", "240", "--views", "1", "--ceiling", "--bands",
                                    "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| 1/4 resolution |" in text and "| held out | 1 |" in text and "| fitted | 1 |" in text
    (report,) = json.loads(out.read_text())
    table = report["ceiling"]
    itself, quarter = table["the reference itself"], table["1/4 resolution"]
    for detector in ("orb", "sift", "akaze"):
        assert itself[detector]["mean"] == 1.0, f"{detector} does not find its own points again: {itself}"
        assert quarter[detector]["mean"] < 1.0, f"{detector} finds every point of a quarter-resolution image"
    assert math.isinf(itself["psnr"]) and quarter["psnr"] < table["1/2 resolution"]["psnr"] < 60
    # a blur removes fine texture, where most of a field's error is: both images agree better after it
    for label in ("held out", "fitted"):
        band = report["bands"][label]["psnr"]
        assert band["plain"] < band["1.0"] < band["4.0"], f"{label}: {band}"


def test_the_fidelity_benchmark_scores_the_nearest_photo_beside_the_render(fidelity_benchmark, tmp_path, capsys):
    out = tmp_path / "neighbours.json"
    assert fidelity_benchmark.main(["demo:wall-field", "--size", "240", "--views", "1", "--neighbours",
                                    "--json", str(out)]) == 0
    assert "| held out | 1 |" in capsys.readouterr().out
    (report,) = json.loads(out.read_text())
    table = report["neighbours"]
    assert {"held out", "fitted"} <= set(table), f"groups: {sorted(table)}"
    for group, part in table.items():
        assert part["nearest"]["reference lengths"] > 0, f"{group}: the nearest other photo is the view itself"
        assert 0.5 < part["nearest"]["share brought"] <= 1, f"{group}: {part['nearest']}"
        field, brought, aligned = (part["rows"][name] for name in fidelity_benchmark.NEIGHBOUR_ROWS)
        # the exact neighbour brought through the field's depth, then aligned by the flow: each closer to the
        # exact reference than the one before (the field's render is blurred; the depth leaves a misplacement)
        assert field["psnr"] < brought["psnr"] < aligned["psnr"], f"{group}: {field}, {brought}, {aligned}"


def test_optical_flow_alignment_undoes_a_shift(fidelity_benchmark):
    import cv2
    import numpy as np

    from pytest_n2r.metrics.image_quality import psnr

    texture = np.random.default_rng(0).integers(0, 256, (48, 64, 3), dtype=np.uint8)
    smooth = cv2.GaussianBlur(texture, (0, 0), 2.0)  # texture the flow can follow
    shifted = np.roll(smooth, 2, axis=1)
    aligned = fidelity_benchmark.aligned_onto(smooth, shifted)
    inner = (slice(8, -8), slice(8, -8))
    assert psnr(smooth[inner], aligned[inner]) > psnr(smooth[inner], shifted[inner]) + 10, (
        f"aligned {psnr(smooth[inner], aligned[inner]):.1f} dB, shifted {psnr(smooth[inner], shifted[inner]):.1f} dB")


def test_the_shift_table_names_its_yardstick_and_says_when_it_has_none():
    from pytest_n2r.relation.floor import FieldFloor, ShiftSample
    from pytest_n2r.study.fidelity import FidelityReport

    def floor(detector: str, score: float) -> FieldFloor:
        sample = ShiftSample("v", score, 1 - score, math.isfinite(score), "" if math.isfinite(score) else "none")
        return FieldFloor("wall", detector, "repeatability", "480", "exact", (sample,), nearby=(sample,),
                          nearby_degrees=3.0)

    floors = {(d, "repeatability"): floor(d, s) for d, s in (("orb", 0.5), ("sift", math.nan), ("akaze", 0.7))}
    exact = FidelityReport("wall", "480", "exact", "", (), floors).format().splitlines()
    assert exact[2].split()[-2:] == ["nearest", "view"], exact
    assert exact[3].split()[-1] == "0.500" and exact[4].split()[-1] == "undefined", exact
    assert exact[6].startswith("  nearest view: the nearest other fitted view's exact render (median 3.0° away)")
    lonely = FidelityReport("fox", "480", "photo", "", (), {}).format().splitlines()
    assert [line.split()[-1] for line in lonely[3:6]] == ["n/a"] * 3, lonely
    assert lonely[6] == "  nearest photo n/a: no other fitted view with a reference image", lonely
