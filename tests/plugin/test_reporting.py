"""Baselines, the CI gate, HTML / JSON reports and JUnit properties, end to end with pytester."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import pytest

from .test_plugin import PLANE

GATED = """
import os


def brightness(rgb):
    '''The SUT: mean brightness; the "candidate" build exaggerates it, so it varies more with the pose.'''
    return float(rgb.mean()) * (3.0 if os.environ.get("N2R_CANDIDATE") else 1.0)


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=8, x=0.1), examples=12)
def test_brightness(n2r_scene):
    return brightness
"""

DERANDOMIZED = ("--n2r-scene", PLANE, "--n2r-derandomize", "yes")


def _row(result: pytest.RunResult, test: str) -> str:
    """The comparison table's row of ``test``."""
    rows = [line for line in result.outlines if line.startswith("test_relations.py::" + test + " ")]
    assert len(rows) == 1, f"no comparison row for {test}:\n{result.stdout.str()}"
    return rows[0]


def test_baseline_then_compare_passes_unchanged_and_fails_a_regression(n2r_project, monkeypatch):
    n2r_project.write(GATED)
    base = n2r_project.pytester.path / "baseline.json"
    saved = n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", str(base))
    saved.assert_outcomes(passed=1)
    data = json.loads(base.read_text())
    (relation,) = data["relations"].values()
    assert len(relation["examples"]) == 12 and relation["eps"] == 1000

    same = n2r_project.run(*DERANDOMIZED, "--n2r-compare", str(base))
    assert same.ret == 0, same.stdout.str()
    row = _row(same, "test_brightness[plane]")
    assert row.endswith(" ok"), row

    monkeypatch.setenv("N2R_CANDIDATE", "1")
    worse = n2r_project.run(*DERANDOMIZED, "--n2r-compare", str(base), "--n2r-compare-fail", "mean:0.02")
    worse.assert_outcomes(passed=1)  # the relation itself holds (eps is huge) ...
    assert worse.ret == pytest.ExitCode.TESTS_FAILED, "... but the gate must fail the run"
    assert "worse: mean:0.02 (baseline" in _row(worse, "test_brightness[plane]")
    assert "1 relation(s) regressed against the baseline" in worse.stdout.str()


def test_missing_baseline_and_bad_rules_are_usage_errors(n2r_project):
    n2r_project.write(GATED)
    missing = n2r_project.run("--n2r-scene", PLANE, "--n2r-compare", "nope.json")
    assert missing.ret == pytest.ExitCode.USAGE_ERROR
    missing.stderr.fnmatch_lines(["*baseline nope.json does not exist; create it with --n2r-save-baseline*"])
    alone = n2r_project.run("--n2r-scene", PLANE, "--n2r-compare-fail", "mean:0.1")
    assert alone.ret == pytest.ExitCode.USAGE_ERROR
    alone.stderr.fnmatch_lines(["*--n2r-compare-fail needs --n2r-compare*"])


def test_html_json_and_junit_reports(n2r_project):
    n2r_project.write(GATED + """

@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=20), examples=30)
def test_heading(n2r_scene):
    return heading_class
""")
    tmp = n2r_project.pytester.path
    result = n2r_project.run("--n2r-scene", "tests.plugin.fakescene:ramp", "--n2r-report", "r.html",
                             "--n2r-json", "r.json", "--junitxml", "j.xml")
    result.assert_outcomes(passed=1, failed=1)
    result.stdout.fnmatch_lines(["*pytest-n2r wrote r.json*", "*pytest-n2r wrote r.html*"])
    page = (tmp / "r.html").read_text()
    assert page.count('aria-label="histogram of deviations"') == 2
    assert "Minimal failing example" in page and "data:image/png;base64," in page
    records = {r["nodeid"].split("::")[-1]: r for r in json.loads((tmp / "r.json").read_text())["relations"]}
    assert records["test_heading[ramp]"]["outcome"] == "failed" and records["test_heading[ramp]"]["minimal"]
    props = {
        (case.get("name"), p.get("name")): p.get("value")
        for case in ET.parse(tmp / "j.xml").iter("testcase") for p in case.iter("property")
    }
    brightness = records["test_brightness[ramp]"]
    assert props[("test_brightness[ramp]", "n2r_examples")] == str(len(brightness["examples"]) - sum(
        not e["valid"] for e in brightness["examples"]))
    assert props[("test_heading[ramp]", "n2r_inconsistencies")] != "0"
