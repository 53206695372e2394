"""`n2r info`: strict JSON whatever the shift measured, and --shift on a splat scene file says why it cannot."""

from __future__ import annotations

import json
import math

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
    assert f"n2r info: error: --shift is not supported for splat scene files: {splat_file} holds the splats" in err
    assert not out, f"printed the summary as if --shift had been measured:\n{out}"
    assert main(["info", str(splat_file), "--json"]) == 0
    assert _strict(capsys.readouterr().out)["representation"] == "splats"
