"""The reporting outputs end to end with pytester: the gate's verdict survives whatever happens to the files,
output paths are checked before the run, a baseline holds every relation of the session it was saved from, and
a user's metric compares with itself."""

from __future__ import annotations

import json
import re

import pytest

import pytest_n2r.report.html
from pytest_n2r.strategies import Brightness

from .test_plugin import PLANE, RAMP
from .test_reporting import DERANDOMIZED, _row

MUTATED = """
import os

from pytest_n2r.strategies import brightness


def brighter(rgb):
    '''The SUT: mean brightness; the "candidate" build exaggerates it, so it varies more with the mutation.'''
    return float(rgb.mean()) * (3.0 if os.environ.get("N2R_CANDIDATE") else 1.0)


@metamorphic(AbsDifference(), eps=float(os.environ.get("N2R_EPS", "1000")), transform=brightness(128), examples=10)
def test_bright(n2r_scene):
    return brighter
"""


def test_a_failing_mutation_relation_is_reported_and_the_gate_keeps_its_verdict(n2r_project, monkeypatch):
    n2r_project.write(MUTATED)
    base = str(n2r_project.pytester.path / "baseline.json")
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", base).assert_outcomes(passed=1)
    monkeypatch.setenv("N2R_CANDIDATE", "1")
    monkeypatch.setenv("N2R_EPS", "5")
    result = n2r_project.run(*DERANDOMIZED, "--n2r-compare", base, "--n2r-report", "r.html")
    text = result.stdout.str() + result.stderr.str()
    assert "INTERNALERROR" not in text, f"the report of a mutation relation crashed the session:\n{text}"
    result.assert_outcomes(failed=1)
    assert result.ret == pytest.ExitCode.TESTS_FAILED, text
    verdict = _row(result, "test_bright[plane]")[-1]  # worse, and its eps changed too (the note says from what)
    assert verdict.startswith("worse+changed-eps (fails)"), f"the gate's verdict is missing: {verdict}"
    page = (n2r_project.pytester.path / "r.html").read_text()
    shown = re.search(r"mutation <code>brightness ([+-]\d+) levels ", page)
    assert shown, "the minimal example's mutation is not in the report"
    words = Brightness(levels=int(shown.group(1))).describe()  # the words failure messages use
    assert f"mutation <code>{words}</code>" in page, f"the minimal example's mutation is not shown as {words!r}"


def test_an_output_that_cannot_be_written_does_not_hide_the_verdict_or_the_others(n2r_project, monkeypatch):
    n2r_project.write(MUTATED)
    base = str(n2r_project.pytester.path / "baseline.json")
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", base).assert_outcomes(passed=1)

    def disk_full(path, *args, **kwargs):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(pytest_n2r.report.html, "write_html", disk_full)
    same = n2r_project.run(*DERANDOMIZED, "--n2r-compare", base, "--n2r-report", "r.html", "--n2r-json", "r.json")
    text = same.stdout.str() + same.stderr.str()
    assert "INTERNALERROR" not in text and "Traceback" not in text, text
    assert _row(same, "test_bright[plane]")[-1] == "ok", "the gate's verdict is missing"
    same.stdout.fnmatch_lines(["*pytest-n2r wrote r.json*",
                               "*pytest-n2r could not write the HTML report r.html: No space left on device*"])
    assert same.ret == pytest.ExitCode.TESTS_FAILED, "a requested report that was not written must fail the run"


TWO = """

@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=20), examples=30)
def test_heading(n2r_scene):
    return heading_class


@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=4), examples=6)
def test_mean_colour(n2r_scene):
    return mean_colour
"""


@pytest.mark.parametrize("stop", [["-x"], ["--maxfail", "1"], ["interrupt"], ["-x", "-n", "2", "-p", "no:benchmark"]],
                         ids=["-x", "--maxfail", "Ctrl-C", "xdist -x"])
def test_a_session_that_stopped_early_saves_no_baseline(n2r_project, stop):
    if "-n" in stop:
        pytest.importorskip("xdist")
    stop_test = "\n\ndef test_interrupt():\n    raise KeyboardInterrupt\n" if stop == ["interrupt"] else ""
    n2r_project.write(TWO.replace("\n\n@metamorphic(Abs", stop_test + "\n\n@metamorphic(Abs", 1))
    base = n2r_project.pytester.path / "baseline.json"
    args = [] if stop == ["interrupt"] else stop
    result = n2r_project.pytester.runpytest("-p", "no:cacheprovider", "--n2r-size", "96", "--n2r-scene", RAMP, *args,
                                            "--n2r-save-baseline", str(base), "--n2r-json", "r.json",
                                            "--n2r-report", "r.html", no_reraise_ctrlc=True)
    assert not base.exists(), f"a baseline was saved from a session stopped by {stop}: it lacks test_mean_colour"
    assert result.ret != pytest.ExitCode.OK, result.stdout.str()
    expected = f"*pytest-n2r did not save the baseline {base}: the session *, so it would lack the relations that did*"
    result.stdout.fnmatch_lines([expected])
    # the reports are still written (what ran is worth seeing), but say they are partial
    report = json.loads((n2r_project.pytester.path / "r.json").read_text())
    assert report["complete"] is False and report["incomplete"].startswith("the session "), report.get("incomplete")
    page = (n2r_project.pytester.path / "r.html").read_text()
    assert "<strong>Partial report:</strong> the session " in page, "the HTML report of a stopped session is unmarked"
    result.stdout.fnmatch_lines(["*pytest-n2r wrote r.json (partial: the session *"])


@pytest.mark.parametrize("args", [["--collect-only"], ["-k", "no_such_test"]], ids=["--collect-only", "-k nothing"])
def test_a_session_that_records_no_relation_keeps_the_baseline(n2r_project, args):
    """Such a session once replaced a good baseline with one of no relations, which the next comparison refused."""
    n2r_project.write(TWO)
    base = n2r_project.pytester.path / "baseline.json"
    base.write_text("the previous baseline\n")
    result = n2r_project.run("--n2r-scene", RAMP, *args, "--n2r-save-baseline", str(base), "--n2r-json", "r.json")
    assert base.read_text() == "the previous baseline\n", "the baseline was replaced by one of no relations"
    why = ("--collect-only ran no test" if "--collect-only" in args else
           "no relation test ran in this session (none was collected, or every one was deselected with -k *")
    said = (f"*pytest-n2r did not save the baseline {base}: {why}, so it would hold no relation (a later "
            "--n2r-compare refuses such a baseline)*; the previous file is left as it was")
    result.stdout.fnmatch_lines([said])
    assert result.ret != pytest.ExitCode.OK
    report = json.loads((n2r_project.pytester.path / "r.json").read_text())
    assert report["complete"] is ("--collect-only" not in args), report


@pytest.mark.parametrize("workers", [[], ["-n", "2", "-p", "no:benchmark"]], ids=["one process", "xdist"])
def test_relations_deselected_when_the_baseline_was_saved_are_missing_later(n2r_project, workers):
    if workers:
        pytest.importorskip("xdist")
    n2r_project.write(TWO)
    base = n2r_project.pytester.path / "baseline.json"
    saved = n2r_project.run("--n2r-scene", RAMP, "-k", "mean_colour", *workers, "--n2r-save-baseline", str(base))
    saved.assert_outcomes(passed=1)
    meta = json.loads(base.read_text())["meta"]
    assert meta["not_recorded"] == ["test_relations.py::test_heading[ramp]"], f"meta {meta}"
    # where the baseline came from (it recorded nothing before: "meta": {})
    assert set(meta) == {"not_recorded", "pytest_n2r", "saved", "rootdir", "config_file", "size", "examples",
                         "derandomize", "scenes"}, meta
    # the places relative (the baseline's folder is the rootdir here): a committed baseline names nobody's home folder
    assert (meta["rootdir"], meta["scenes"], meta["derandomize"]) == (".", ["ramp"], False), meta
    assert str(n2r_project.pytester.path) not in base.read_text(), "an absolute path in the baseline"
    full = n2r_project.run("--n2r-scene", RAMP, "--n2r-compare", str(base))
    assert _row(full, "test_heading[ramp]")[-1] == "missing (fails)", \
        "a relation the baseline's session deselected must not pass as new"
    assert full.ret == pytest.ExitCode.TESTS_FAILED
    full.stdout.fnmatch_lines(["*test_heading[[]ramp[]]: missing: not in the baseline: the session that saved it *"])


@pytest.mark.parametrize(("args", "expected"), [
    (["--n2r-json", "{tmp}"], "--n2r-json: {tmp} is a folder; expected the path of a file to write"),
    (["--n2r-report", "{tmp}/notes.txt/r.html"], "--n2r-report: {tmp}/notes.txt/r.html: {tmp}/notes.txt is a file"),
    (["--n2r-save-baseline", "/proc/n2r-baseline.json"],
     "--n2r-save-baseline: /proc/n2r-baseline.json: cannot write into /proc"),
    (["--n2r-json", "out.json", "--n2r-report", "out.json"], "--n2r-json and --n2r-report are both out.json"),
    (["--n2r-json", "out.json", "--n2r-report", "sub/../out.json"],
     "--n2r-json out.json and --n2r-report sub/../out.json are one file ({tmp}/out.json)"),
    # a report over the baseline being compared with once replaced it: the next comparison failed reading a report
    (["--n2r-compare", "base.json", "--n2r-json", "base.json"],
     ("--n2r-compare and --n2r-json are both base.json; give the report its own file (it would replace the "
      "baseline this run compares with)")),
    (["--n2r-compare", "base.json", "--n2r-report", "sub/../base.json"],
     "--n2r-compare base.json and --n2r-report sub/../base.json are one file ({tmp}/base.json); give the report"),
    # pytest's JUnit XML, or pytest-html's page (a stand-in plugin declares --html), on an n2r output silently
    # replaced it (or was replaced)
    (["--n2r-json", "same.out", "--junitxml", "same.out"],
     "--n2r-json and --junitxml are both same.out; give each output its own file (one would replace the other)"),
    (["-p", "fakehtml", "--n2r-report", "r.html", "--html", "sub/../r.html"],
     "--n2r-report r.html and --html sub/../r.html are one file ({tmp}/r.html); give each output its own file"),
])
def test_output_paths_are_checked_before_the_run(n2r_project, args, expected):
    tmp = n2r_project.pytester.path
    (tmp / "notes.txt").write_text("my notes\n")
    n2r_project.pytester.syspathinsert()
    n2r_project.pytester.makepyfile(fakehtml="def pytest_addoption(parser):\n"
                                             "    parser.addoption('--html', dest='htmlpath')\n")
    n2r_project.write(TWO)
    result = n2r_project.run("--n2r-scene", PLANE, *(a.format(tmp=tmp) for a in args))
    err = " ".join(result.stderr.str().split())
    assert result.ret == pytest.ExitCode.USAGE_ERROR, f"exit code {result.ret}:\n{result.stdout.str()}\n{err}"
    assert f"ERROR: pytest-n2r: {expected.format(tmp=tmp)}" in err, err


def test_a_tilde_in_a_baseline_path_given_with_equals_is_the_home_folder(n2r_project, monkeypatch):
    """No shell expands a ~ after '=': the baseline was saved in the home folder, then not found to compare with,
    nor seen to be the file a report or a regressed run would replace."""
    home = n2r_project.pytester.path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    n2r_project.write(MUTATED)
    derandomized = ("--n2r-scene", PLANE, "--n2r-derandomize", "yes")
    n2r_project.run(*derandomized, "--n2r-save-baseline=~/b.json").assert_outcomes(passed=1)
    assert (home / "b.json").is_file()
    same = n2r_project.run(*derandomized, "--n2r-compare=~/b.json")
    assert same.ret == pytest.ExitCode.OK, same.stdout.str() + same.stderr.str()
    assert _row(same, "test_bright[plane]")[-1] == "ok"
    clash = n2r_project.run(*derandomized, "--n2r-compare=~/b.json", "--n2r-json=home/b.json")
    assert clash.ret == pytest.ExitCode.USAGE_ERROR
    assert (f"--n2r-compare {home / 'b.json'} and --n2r-json home/b.json are one file ({home / 'b.json'}); give the "
            "report its own file") in " ".join(clash.stderr.str().split()), clash.stderr.str()
    monkeypatch.setenv("N2R_CANDIDATE", "1")
    before = (home / "b.json").read_text()
    worse = n2r_project.run(*derandomized, "--n2r-compare=~/b.json", "--n2r-save-baseline=~/b.json")
    assert worse.ret == pytest.ExitCode.TESTS_FAILED and (home / "b.json").read_text() == before, \
        "a regressed run replaced the baseline it failed against"
    worse.stdout.fnmatch_lines([(f"*did not save the baseline {home / 'b.json'}: it is the baseline this run compared "
                                "with (--n2r-compare), and 1 relation(s) failed the comparison*")])


def test_collect_only_does_not_compare(n2r_project):
    """Nothing ran, so every relation was 'missing: collected, then deselected' and the run failed."""
    n2r_project.write(TWO)
    base = n2r_project.pytester.path / "baseline.json"
    n2r_project.run("--n2r-scene", RAMP, "-k", "mean_colour", f"--n2r-save-baseline={base}").assert_outcomes(passed=1)
    listed = n2r_project.run("--n2r-scene", RAMP, "--collect-only", "-k", "mean_colour", f"--n2r-compare={base}")
    assert listed.ret == pytest.ExitCode.OK, listed.stdout.str()
    listed.stdout.fnmatch_lines([(f"pytest-n2r baseline {base}: --collect-only ran no test, so nothing was compared "
                                 "with the baseline")])
    assert "missing" not in listed.stdout.str() and "baseline comparison" not in listed.stdout.str()


SCENE_MODULE = """
from tests.plugin.fakescene import PlaneScene


def make():
    return PlaneScene()
"""


def test_a_module_function_scene_is_compared_by_the_name_its_relations_carry(n2r_project):
    """``myscenes:make`` is configured as 'make' (the test ids, ``meta.scenes``) and loads a scene named 'plane'
    (the relation records): a relation added on it was told "the scene set differs" though nothing differed."""
    n2r_project.pytester.makepyfile(myscenes=SCENE_MODULE)
    n2r_project.write(TWO)
    base = n2r_project.pytester.path / "baseline.json"
    scene = ("--n2r-scene", "myscenes:make")
    n2r_project.run(*scene, "-k", "mean_colour", f"--n2r-save-baseline={base}").assert_outcomes(passed=1)
    saved = json.loads(base.read_text())
    assert saved["meta"]["scenes"] == ["make"], saved["meta"]
    assert [r["scene"] for r in saved["relations"].values()] == ["plane"], saved["relations"]
    data = json.loads(base.read_text())
    data["meta"].pop("not_recorded")  # the relation is new, not one the baseline's session deselected
    base.write_text(json.dumps(data))
    both = n2r_project.run(*scene, f"--n2r-compare={base}")  # test_heading fails on the plane: not the gate's verdict
    assert _row(both, "test_heading[make]")[-1] == "new"
    both.stdout.fnmatch_lines([("*test_heading[[]make[]]: new: not in the baseline: nothing to compare with (save a "
                               "new baseline to include it)")])
    assert "scene set differs" not in both.stdout.str()


def test_a_users_metric_without_a_repr_compares_with_itself(n2r_project):
    """A metric subclass without ``__repr__`` of its own once read as ``<MyDiff object at 0x...>``: a new
    address every run, so every comparison said changed-metric."""
    n2r_project.write("""
from pytest_n2r.metrics.base import Metric


class MyDiff(Metric):
    name = "my_diff"
    ideal = 0.0

    def __init__(self, scale=1.0):
        self.scale = scale

    def compute(self, out_source, out_follow, source, follow):
        return self.result(abs(float(out_source) - float(out_follow)) * self.scale)


@metamorphic(MyDiff(0.5), eps=1000, transform=transforms(yaw=4), examples=6)
def test_mine(n2r_scene):
    return mean_colour
""")
    base = n2r_project.pytester.path / "baseline.json"
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", str(base)).assert_outcomes(passed=1)
    (relation,) = json.loads(base.read_text())["relations"].values()
    assert relation["metric"] == "MyDiff(scale=0.5)", relation["metric"]
    again = n2r_project.run(*DERANDOMIZED, "--n2r-compare", str(base))
    assert _row(again, "test_mine[plane]")[-1] == "ok", "an unchanged user metric must compare as ok"
    assert again.ret == pytest.ExitCode.OK


def test_two_other_plugins_sharing_a_file_is_not_pytest_n2rs_to_refuse(n2r_project):
    """``--junitxml`` and ``--html`` on one file is pytest's and pytest-html's clash: pytest-n2r (checking its own
    outputs against theirs) says nothing of it."""
    n2r_project.pytester.syspathinsert()
    n2r_project.pytester.makepyfile(fakehtml="def pytest_addoption(parser):\n"
                                             "    parser.addoption('--html', dest='htmlpath')\n")
    n2r_project.write(TWO)
    result = n2r_project.run("-p", "fakehtml", "--n2r-scene", PLANE, "--n2r-json", "r.json", "--junitxml", "o.xml",
                             "--html", "o.xml")
    assert "pytest-n2r:" not in result.stderr.str(), result.stderr.str()
    assert result.ret != pytest.ExitCode.USAGE_ERROR, result.stdout.str()
