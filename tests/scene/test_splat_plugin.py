"""A user with a .ply from a GPU tool writes ``--n2r-scene scene.ply``: the plugin's @metamorphic tests, the
JSON report, the baseline gate and ``n2r study`` work on it unchanged (pytester)."""

from __future__ import annotations

import json

import pytest

# pytester drops the modules an inner run imported first; importing them here keeps one copy of each (see
# tests/plugin/conftest.py).
import pytest_n2r.metrics
import pytest_n2r.plugin.marker
import pytest_n2r.scene.splat_scene
import pytest_n2r.strategies  # noqa: F401
from pytest_n2r.cli.main import main

from ..splats.make_data import DATA, FILES

INNER = """
import cv2
import numpy as np
from pytest_n2r import SplatScene, l2_norm, metamorphic, transforms
from pytest_n2r.metrics import repeatability


def test_the_fixture_is_the_splat_scene(n2r_scene):
    assert isinstance(n2r_scene, SplatScene), type(n2r_scene)
    assert len(n2r_scene.views) == 48 and n2r_scene.gaussians.sh_degree == 0, n2r_scene


@metamorphic(l2_norm(inputs="raw"), eps=0.2, transform=transforms(yaw=(-3, 3)), examples=4)
def test_mean_colour(n2r_scene):
    return lambda rgb: [float(rgb.mean()) / 255.0]


def orb(rgb):
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    return np.array([k.pt for k in cv2.ORB_create(200).detect(gray)], dtype=np.float32).reshape(-1, 2)


@metamorphic(repeatability(px=3), eps=0.9, transform=transforms(x=(-0.02, 0.02)), examples=3)
def test_orb_repeatability(n2r_scene):
    return orb
"""


def test_metamorphic_tests_and_reports_run_on_a_ply(pytester: pytest.Pytester, monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    pytester.makepyfile(test_inner=INNER)
    ply = DATA / FILES["object-sh0"][0]
    report = pytester.path / "n2r.json"
    # derandomized: the same examples every run (ORB on a few-thousand-Gaussian scene is no steady SUT)
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene=" + str(ply), "--n2r-size", "240",
                                "--n2r-derandomize", "yes",
                                "--n2r-json", str(report), "--n2r-save-baseline=" + str(pytester.path / "base.json"),
                                "--n2r-report", str(pytester.path / "report.html"))
    result.assert_outcomes(passed=3)
    result.stdout.fnmatch_lines(["*test_mean_colour[[]point_cloud[]]*4 examples*"])
    records = json.loads(report.read_text())
    assert "point_cloud" in json.dumps(records), "the JSON report names the splat scene"
    assert "point_cloud" in (pytester.path / "report.html").read_text(), "the HTML report names the splat scene"
    gate = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene=" + str(ply), "--n2r-size", "240",
                              "--n2r-derandomize", "yes",
                              "--n2r-compare=" + str(pytester.path / "base.json"))
    gate.assert_outcomes(passed=3)


def test_a_ply_without_cameras_fails_the_relation_with_the_reason(pytester: pytest.Pytester, tmp_path, monkeypatch):
    import shutil

    monkeypatch.delenv("CI", raising=False)
    lone = tmp_path / "lone.ply"
    shutil.copy(DATA / FILES["object-sh0"][0], lone)
    pytester.makepyfile(test_inner="""
from pytest_n2r import l2_norm, metamorphic, transforms


@metamorphic(l2_norm(inputs="raw"), eps=0.2, transform=transforms(yaw=3), examples=2)
def test_mean_colour(n2r_scene):
    return lambda rgb: [float(rgb.mean())]
""")
    result = pytester.runpytest("-p", "no:cacheprovider", "--n2r-scene=" + str(lone), "--n2r-size", "64")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines([("*scene 'lone' has no views to use as sources: no cameras were given and none were "
                                  "found beside*")])


def test_n2r_study_runs_on_a_splat_scene(tmp_path, capsys):
    code = main(["study", str(DATA / FILES["wall-sh3"][0]), "--sut", "orb", "-o", str(tmp_path), "--examples", "1",
                 "--views", "1", "--size", "64", "--fps-size", "64x36", "--fps-frames", "1"])
    assert code == 0, capsys.readouterr().err
    assert (tmp_path / "study.md").is_file() and (tmp_path / "examples.csv").is_file()
    assert "splat" in (tmp_path / "study.md").read_text()


GATED = """
import os

from pytest_n2r import l2_norm, metamorphic, transforms


@metamorphic(l2_norm(inputs="raw"), eps=1000.0, transform=transforms(yaw=(-3, 3)), examples=8)
def test_mean_colour(n2r_scene):
    gain = float(os.environ["N2R_TEST_GAIN"])  # a larger gain: the same relation, a worse SUT
    return lambda rgb: [gain * float(rgb.mean()) / 255.0]
"""


def test_the_gate_on_a_ply_passes_the_same_sut_and_fails_a_worse_one_or_a_retrained_scene(
        pytester: pytest.Pytester, monkeypatch):
    """Baseline on a .ply (with JUnit properties), then ``--n2r-compare``: the same SUT is ``ok`` and the run
    passes; the SUT made worse (its deviations 2000 times larger, still far inside ``eps``) is ``worse`` and
    fails the run although the relation holds; the same file trained again (other content) is
    ``changed-scene``."""
    import shutil
    import xml.etree.ElementTree as ET

    from pytest_n2r.splats import read_ply, write_ply

    monkeypatch.delenv("CI", raising=False)
    pytester.makepyfile(test_gated=GATED)
    ply = DATA / FILES["object-sh0"][0]
    common = ("-p", "no:cacheprovider", "--n2r-size", "96", "--n2r-derandomize", "yes")
    base, junit = pytester.path / "base.json", pytester.path / "junit.xml"
    monkeypatch.setenv("N2R_TEST_GAIN", "1")
    saved = pytester.runpytest(*common, "--n2r-scene=" + str(ply), "--n2r-save-baseline=" + str(base),
                               "--junitxml", str(junit))
    saved.assert_outcomes(passed=1)
    properties = {p.get("name"): p.get("value") for p in ET.parse(junit).iter("property")}
    assert properties.get("n2r_scene") == "point_cloud" and properties.get("n2r_examples") == "8", properties
    assert {"n2r_metric", "n2r_eps", "n2r_worst_deviation"} <= set(properties), properties

    same = pytester.runpytest(*common, "--n2r-scene=" + str(ply), "--n2r-compare=" + str(base))
    same.assert_outcomes(passed=1)
    assert same.ret == 0, same.stdout.str()

    monkeypatch.setenv("N2R_TEST_GAIN", "2000")
    worse = pytester.runpytest(*common, "--n2r-scene=" + str(ply), "--n2r-compare=" + str(base))
    worse.assert_outcomes(passed=1)
    assert worse.ret == 1, f"the gate let a worse SUT through:\n{worse.stdout.str()}"
    worse.stdout.fnmatch_lines(["*worse*"])

    monkeypatch.setenv("N2R_TEST_GAIN", "1")
    retrained = pytester.path / "retrained"
    shutil.copytree(DATA / "object-sh0", retrained)
    g = read_ply(ply)
    tensors = g.tensors()
    tensors["opacity_logits"] = tensors["opacity_logits"] - 0.5
    write_ply(retrained / ply.relative_to(DATA / "object-sh0"), type(g)(**tensors))
    changed = pytester.runpytest(*common, "--n2r-scene=" + str(retrained / ply.relative_to(DATA / "object-sh0")),
                                 "--n2r-compare=" + str(base))
    assert changed.ret == 1, f"a retrained scene passed the gate:\n{changed.stdout.str()}"
    changed.stdout.fnmatch_lines(["*changed-scene*"])
