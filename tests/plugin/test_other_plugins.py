"""pytest-n2r beside other pytest plugins, simulated here by what they do (neither is installed in the test
environment): pytest-rerunfailures' ``--reruns`` (one test id run twice, the first try reported as ``rerun``),
pytest-timeout's signal method (pytest's ``Failed`` raised inside a SUT call) and its thread method (the process
ended by ``os._exit``, leaving whatever report files are on disk)."""

from __future__ import annotations

import json

import pytest

from .test_plugin import PLANE

#: What pytest-rerunfailures does (``pytest_rerunfailures.pytest_runtest_protocol``): run the protocol again while
#: a try failed, that try's failed reports logged with outcome ``rerun`` and every report numbered by ``rerun``.
FAKE_RERUNS = """

from _pytest.runner import runtestprotocol


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_protocol(item, nextitem):
    for attempt in range(2):
        item.ihook.pytest_runtest_logstart(nodeid=item.nodeid, location=item.location)
        reports = runtestprotocol(item, nextitem=nextitem, log=False)
        again = attempt == 0 and any(r.failed for r in reports)
        for report in reports:
            report.rerun = attempt
            if again and report.failed:
                report.outcome = "rerun"
            item.ihook.pytest_runtest_logreport(report=report)
        if not again:
            break
    item.ihook.pytest_runtest_logfinish(nodeid=item.nodeid, location=item.location)
    return True


def pytest_report_teststatus(report):
    if report.outcome == "rerun":
        return "rerun", "R", ("RERUN", {"yellow": True})
"""

FLAKY = """
import os

TRIES = []


def crash(rgb):
    raise RuntimeError("first try crashes")


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_flaky(n2r_scene):
    TRIES.append(1)
    return crash if os.environ.get("N2R_FLAKY") and len(TRIES) == 1 else mean_colour


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_steady(n2r_scene):
    return mean_colour
"""


@pytest.mark.parametrize("xdist", [(), ("-n", "2")], ids=["one-process", "xdist"])
def test_a_rerun_relation_has_one_record_in_every_output(n2r_project, monkeypatch, xdist):
    """With pytest-rerunfailures, a relation that failed its first try and passed its rerun was recorded twice: the
    gate compared the failed try too and failed a green run, the summary counted 3 relations for 2, the JSON listed
    the test twice (failed, then passed), the HTML too; the baseline kept one."""
    pytester = n2r_project.pytester
    conftest = pytester.path / "conftest.py"
    conftest.write_text(conftest.read_text() + "\nimport pytest\n" + FAKE_RERUNS)
    n2r_project.write(FLAKY)
    saved = n2r_project.run("--n2r-scene", PLANE, "--n2r-save-baseline", "base.json")
    saved.assert_outcomes(passed=2)
    monkeypatch.setenv("N2R_FLAKY", "1")
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-compare", "base.json", "--n2r-json", "r.json",
                             "--n2r-report", "r.html", *xdist)
    out = result.stdout.str()
    assert result.parseoutcomes().get("rerun") == 1, out
    assert result.ret == 0, f"the rerun's first try failed the baseline gate of a green run:\n{out}"
    assert "2 relations: " in out, out
    flaky = [line for line in result.outlines if line.startswith(("PASSED", "ERROR")) and "::test_flaky[" in line]
    assert len(flaky) == 1 and flaky[0].startswith("PASSED"), flaky
    assert flaky[0].endswith("; rerun: 1 earlier try under this test id dropped, the last one counts"), flaky[0]
    relations = json.loads((pytester.path / "r.json").read_text())["relations"]
    shown = sorted((r["nodeid"].split("::")[-1], r["outcome"], r.get("reruns", 0)) for r in relations)
    assert shown == [("test_flaky[plane]", "passed", 1), ("test_steady[plane]", "passed", 0)], shown
    page = (pytester.path / "r.html").read_text()
    assert page.count('<h2 id="rel') == 2 and "first try crashes" not in page, "the HTML shows the first try"


TIMEOUT = """
CALLS = []


def times_out_once(rgb):
    CALLS.append(1)
    if len(CALLS) == 1:  # pytest-timeout's signal method: pytest.fail in the signal handler, in the SUT's call
        pytest.fail("Timeout (>2.0s) from pytest-timeout.")
    return mean_colour(rgb)


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=5)
def test_slow(n2r_scene):
    return times_out_once
"""


def test_pytests_failed_raised_in_one_example_is_reported_as_itself(n2r_project):
    """pytest-timeout's ``Failed`` in one example, not again when Hypothesis replayed it: the user saw Hypothesis's
    ``_WrappedBaseException`` with pytest-n2r's note that it was neither the SUT nor the verdict, never "Timeout",
    and the pytest-n2r summary said ERROR where pytest said FAILED."""
    n2r_project.write(TIMEOUT)
    result = n2r_project.run("--n2r-scene", PLANE, "--n2r-json", "r.json")
    result.assert_outcomes(failed=1)
    out = result.stdout.str()
    assert "Failed: Timeout (>2.0s) from pytest-timeout." in out, out
    assert "_WrappedBaseException" not in out and "not when Hypothesis replayed it" not in out, out
    line = n2r_project.summary(result, "test_slow[plane]")
    assert line.startswith("FAILED "), f"pytest says FAILED, the summary: {line}"
    (relation,) = json.loads((n2r_project.pytester.path / "r.json").read_text())["relations"]
    assert relation["pytest_outcome"] == "failed", relation["pytest_outcome"]
    assert relation["message"] == "Failed: Timeout (>2.0s) from pytest-timeout.", relation["message"]


DIES = """
import os


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=5), examples=3)
def test_holds(n2r_scene):
    return mean_colour


def test_zz_dies():
    os._exit(3)  # pytest-timeout's thread method
"""

STALE = {"complete": True, "relations": [{"nodeid": "old"}], "not_run": []}


def test_a_session_that_dies_leaves_no_report_that_looks_current(n2r_project):
    """pytest-timeout's thread method ends the process with ``os._exit``: the previous run's JSON and HTML reports
    stayed, ``"complete": true``, as if this session had written them."""
    pytester = n2r_project.pytester
    (pytester.path / "r.json").write_text(json.dumps(STALE))
    (pytester.path / "r.html").write_text("<html><body>the previous run's report</body></html>")
    n2r_project.write(DIES)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--n2r-size", "96", "--n2r-scene", PLANE,
                                           "--n2r-json", "r.json", "--n2r-report", "r.html")
    assert result.ret == 3, result.stdout.str()
    payload = json.loads((pytester.path / "r.json").read_text())
    assert payload["complete"] is False and "has not finished" in payload["incomplete"], payload
    assert payload["relations"] == [], payload
    page = (pytester.path / "r.html").read_text()
    assert "previous run" not in page and "not finished" in page, page
    # a run that starts no test (--collect-only) writes its own partial report at its finish, no placeholder
    pytester.runpytest("-p", "no:cacheprovider", "--co", "--n2r-scene", PLANE, "--n2r-json", "r.json")
    payload = json.loads((pytester.path / "r.json").read_text())
    assert payload["incomplete"] == "--collect-only ran no test", payload



def test_a_test_run_twice_under_one_id_says_the_earlier_run_was_dropped(n2r_project, monkeypatch):
    """pytest --keep-duplicates runs a file given twice twice, under the same ids and without a 'rerun' report: the
    first run's failure vanished from the summary, the JSON and the gate without a word."""
    monkeypatch.setenv("N2R_FLAKY", "1")
    n2r_project.write(FLAKY)
    name = next(n2r_project.pytester.path.glob("test_*.py")).name
    result = n2r_project.run("--keep-duplicates", name, name, "--n2r-scene", PLANE, "--n2r-json", "r.json",
                             "--n2r-report", "r.html")
    result.assert_outcomes(failed=1, passed=3)
    line = n2r_project.summary(result, "test_flaky[plane]")
    assert line.endswith("; rerun: 1 earlier try under this test id dropped, the last one counts"), line
    relations = json.loads((n2r_project.pytester.path / "r.json").read_text())["relations"]
    flaky = [r for r in relations if r["nodeid"].endswith("test_flaky[plane]")]
    assert len(relations) == 2 and flaky[0]["reruns"] == 1 and flaky[0]["outcome"] == "passed", relations
    page = (n2r_project.pytester.path / "r.html").read_text()
    row = page.split("test_flaky[plane]</a></td>", 1)[1].split("</tr>", 1)[0]
    section = page.split("test_flaky[plane]</h2>", 1)[1].split("</p>", 1)[0]
    for where, text in (("table row", row), ("section", section)):
        assert "passed after 1 earlier try under this test id (the last counts)" in text.replace("</span>", ""), \
            f"the HTML report's {where} should say the relation passed on its second try: {text}"


def test_at_qq_a_relation_that_passed_only_on_its_rerun_is_still_shown(n2r_project, monkeypatch):
    """``-qq`` leaves out the relations that passed plainly; one that passed on its rerun stays, with its rerun,
    since a CI log should keep the sign that it is flaky."""
    conftest = n2r_project.pytester.path / "conftest.py"
    conftest.write_text(conftest.read_text() + "\nimport pytest\n" + FAKE_RERUNS)
    n2r_project.write(FLAKY)
    monkeypatch.setenv("N2R_FLAKY", "1")
    result = n2r_project.run("--n2r-scene", PLANE, "-qq")
    shown = [line for line in result.outlines if "::test_" in line and line.startswith(("PASSED", "ERROR"))]
    assert len(shown) == 1 and "::test_flaky[" in shown[0], "\n".join(result.outlines)
    assert shown[0].endswith("; rerun: 1 earlier try under this test id dropped, the last one counts"), shown[0]
