"""What the JSON and HTML reports say of each relation test: pytest's own outcome (xfailed, xpassed, a strict
xfail's pass failing the run), the relation tests that ended without running their relation, and comparison
numbers a strict JSON reader accepts."""

from __future__ import annotations

import json
import re

import pytest

from .test_plugin import PLANE

XFAIL = """
@pytest.mark.xfail(strict=True, reason="known")
@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_strict(n2r_scene):
    return mean_colour


@pytest.mark.xfail(reason="known")
@metamorphic(AbsDifference(), eps=1e-9, transform=transforms(yaw=5), examples=5)
def test_xfail(n2r_scene):
    return mean_colour


@pytest.mark.xfail(reason="known")
@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_xpass(n2r_scene):
    return mean_colour
"""


def _outcome_cells(page: str) -> dict[str, tuple[str, str]]:
    """The HTML summary table's outcome cell of each relation: {test name: (class, text)}."""
    rows = re.findall(r'<tr><td><a href="#rel\d+">[^<]*::(\w+)\[plane\]</a></td><td class="([^"]*)">([^<]*)</td>', page)
    return {name: (css, text) for name, css, text in rows}


def test_the_reports_show_pytests_outcome_of_xfail_relations(n2r_project):
    n2r_project.write(XFAIL)
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-json", "r.json", "--n2r-report", "r.html")
    result.assert_outcomes(failed=1, xfailed=1, xpassed=1)
    relations = {r["nodeid"].split("::")[-1]: r for r in json.loads((n2r_project.pytester.path / "r.json").read_text())
                 ["relations"]}
    shown = {name[:-len("[plane]")]: (r["outcome"], r["pytest_outcome"]) for name, r in relations.items()}
    # the strict xfail's pass failed the run (pytest: FAILED [XPASS(strict)]) but the reports said "passed"
    assert shown == {"test_strict": ("passed", "failed"), "test_xfail": ("failed", "xfailed"),
                     "test_xpass": ("passed", "xpassed")}, f"pytest's outcome is not in the JSON report: {shown}"
    page = (n2r_project.pytester.path / "r.html").read_text()
    cells = _outcome_cells(page)
    assert cells == {"test_strict": ("failed", "failed (XPASS(strict): the relation held)"),
                     "test_xfail": ("xfailed", "xfailed"), "test_xpass": ("xpassed", "xpassed")}, \
        f"the HTML shows the relation's verdict, not pytest's outcome: {cells}"
    assert "(shrunk)" not in page, "an xfail relation is not shrunk, but its example is headed as shrunk"
    assert "<h3>Failing example (not shrunk: the test is marked xfail)</h3>" in page


NOT_RUN = """
@pytest.fixture
def model():
    raise OSError("weights not found")


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_fixture_error(n2r_scene, model):
    return mean_colour


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_body_raises(n2r_scene):
    raise ImportError("no cv2")


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_body_skips(n2r_scene):
    pytest.skip("no GPU")


@pytest.mark.skip(reason="later")
@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_marked_skip(n2r_scene):
    return mean_colour


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_crash(n2r_scene):
    import os

    if os.environ.get("PYTEST_XDIST_WORKER") and os.environ.get("N2R_TEST_CRASH_WORKER"):
        os._exit(3)  # the worker dies in the test's body: pytest-xdist reports it crashed
    return mean_colour


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_ok(n2r_scene):
    return mean_colour


def test_plain():
    raise AssertionError("not a relation test")
"""


#: pytest-xdist's words for the worker that died running test_crash (gw0 or gw1: normalised to gw?)
_CRASHED = "worker 'gw?' crashed while running 'test_relations.py::test_crash[plane]'"


@pytest.mark.parametrize("workers", [[], ["-n", "2", "-p", "no:benchmark"]], ids=["one process", "xdist"])
def test_relation_tests_that_did_not_run_their_relation_are_listed(n2r_project, workers, monkeypatch):
    # only the inner run's own workers crash: an in-process run inside an outer pytest-xdist worker sees that
    # worker's PYTEST_XDIST_WORKER, and exiting there killed the outer worker
    if workers:
        monkeypatch.setenv("N2R_TEST_CRASH_WORKER", "1")
    else:
        monkeypatch.delenv("N2R_TEST_CRASH_WORKER", raising=False)
    n2r_project.write(NOT_RUN)
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-json", "r.json", "--n2r-report", "r.html", *workers)
    report = json.loads((n2r_project.pytester.path / "r.json").read_text())
    listed = {t["nodeid"].split("::")[-1]: (t["outcome"], t["reason"]) for t in report["not_run"]}
    expected = {"test_fixture_error[plane]": ("error", "OSError: weights not found"),
                "test_body_raises[plane]": ("failed", "ImportError: no cv2"),
                "test_body_skips[plane]": ("skipped", "Skipped: no GPU"),
                "test_marked_skip[plane]": ("skipped", "Skipped: later")}
    if workers:  # the worker that ran it is named: gw0 or gw1
        expected["test_crash[plane]"] = ("failed", _CRASHED)
        if "test_crash[plane]" in listed:
            listed["test_crash[plane]"] = (listed["test_crash[plane]"][0],
                                           re.sub(r"'gw\d+'", "'gw?'", listed["test_crash[plane]"][1]))
    # they were absent: the report of a run with errors was all green, and said "complete": true
    assert listed == expected, f"the relation tests that did not run are not listed as pytest ended them: {listed}"
    assert report["complete"] is True, "every selected test ran: the report is complete, listing those without records"
    ran = [r["nodeid"].split("::")[-1] for r in report["relations"]]
    assert ran == ([] if workers else ["test_crash[plane]"]) + ["test_ok[plane]"], ran
    page = (n2r_project.pytester.path / "r.html").read_text()
    assert f"<strong>{len(expected)} relation test(s) did not run their relation</strong>" in page, \
        "the HTML does not say that relation tests did not run"
    for name, (outcome, reason) in expected.items():
        if name != "test_crash[plane]":
            assert f'{name}</td><td class="{outcome}">{outcome}</td><td>{reason}</td>' in page, \
                f"the HTML does not list {name} as {outcome}: {reason}"
    assert result.ret == pytest.ExitCode.TESTS_FAILED


ONE_PAIR = """
@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=8, x=0.1), examples=1)
def test_one(n2r_scene):
    return mean_colour
"""


def _strict(constant: str) -> None:
    raise ValueError(f"{constant} is not JSON (a strict reader, like JavaScript's JSON.parse, rejects it)")


def test_the_comparisons_numbers_are_strict_json(n2r_project):
    n2r_project.write(ONE_PAIR)
    base = str(n2r_project.pytester.path / "base.json")
    n2r_project.run("--n2r-scene", PLANE, "--n2r-derandomize", "yes", "--n2r-save-baseline", base) \
        .assert_outcomes(passed=1)
    n2r_project.run("--n2r-scene", PLANE, "--n2r-derandomize", "yes", "--n2r-compare", base, "--n2r-json", "r.json") \
        .assert_outcomes(passed=1)
    comparison = json.loads((n2r_project.pytester.path / "r.json").read_text())["comparison"]
    text = json.dumps(comparison, allow_nan=True)
    # one pair bounds nothing: the bound was written -Infinity, which the docs did not promise and strict readers reject
    [relation] = json.loads(text, parse_constant=_strict)["relations"]
    assert (relation["n"], relation["bound"]) == (1, None), f"one pair's bound is not null: {relation}"


def test_a_json_report_and_its_pictures_moved_together_still_find_each_other(n2r_project, tmp_path):
    """The JSON held the failure pictures' absolute paths on the machine that ran the tests: the HTML rebuilt from a
    JSON report and artifacts folder downloaded from CI said "image /home/runner/... not found" for each."""
    import shutil

    from pytest_n2r.report import RelationRecord
    from pytest_n2r.report.html import render_html

    n2r_project.write("""
@metamorphic(AbsDifference(), eps=1e-9, transform=transforms(yaw=5), examples=3)
def test_breaks(n2r_scene):
    return mean_colour
""")
    here = n2r_project.pytester.path
    n2r_project.run("--n2r-scene", PLANE, "--n2r-json=out/results.json").assert_outcomes(failed=1)
    downloaded = tmp_path / "downloaded"
    shutil.copytree(here / "out", downloaded / "out")
    shutil.copytree(here / "n2r-artifacts", downloaded / "n2r-artifacts")
    shutil.rmtree(here / "n2r-artifacts")
    results = json.loads((downloaded / "out" / "results.json").read_text())
    images = results["relations"][0]["minimal"]["images"]
    assert images and all(not p.startswith("/") and p.startswith("../n2r-artifacts/") for p in images.values()), images
    page = render_html([RelationRecord.from_dict(r) for r in results["relations"]],
                       images_base=downloaded / "out")
    assert "not found" not in page and page.count("data:image/png;base64,") == len(images), (
        "the rebuilt report lost its pictures")


TEARDOWN_FAILS = """
@pytest.fixture
def model():
    yield mean_colour
    raise RuntimeError("the model's file could not be closed")


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=3)
def test_teardown_fails(n2r_scene, model):
    return model
"""


def test_a_relation_whose_teardown_fails_is_an_error_in_every_report(n2r_project):
    """The relation held, then a fixture's teardown raised: pytest says ERROR, and so must the JSON report and the
    summary, not "passed"."""
    n2r_project.write(TEARDOWN_FAILS)
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-json", "r.json", "--n2r-report", "r.html")
    result.assert_outcomes(passed=1, errors=1)
    (relation,) = json.loads((n2r_project.pytester.path / "r.json").read_text())["relations"]
    assert (relation["outcome"], relation["pytest_outcome"]) == ("passed", "error"), relation
    assert n2r_project.summary(result, "test_teardown_fails[plane]").startswith("ERROR"), result.stdout.str()
    cells = _outcome_cells((n2r_project.pytester.path / "r.html").read_text())
    assert cells["test_teardown_fails"][0] == "error", cells
