"""Baselines, the CI gate, HTML / JSON reports and JUnit properties, end to end with pytester."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import pytest

from .test_plugin import DARKEN, PLANE

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


def _row(result: pytest.RunResult, test: str) -> list[str]:
    """The comparison table's row of ``test``, split into its columns (relation, n, mean change, bound, verdict)."""
    rows = [line for line in result.outlines if line.startswith("test_relations.py::" + test + " ")]
    assert len(rows) == 1, f"no comparison row for {test}:\n{result.stdout.str()}"
    return rows[0].split(None, 4)


def _json(project, name: str) -> dict:
    return {r["nodeid"].split("::")[-1]: r for r in json.loads((project.pytester.path / name).read_text())["relations"]}


def test_baseline_then_paired_replay_passes_unchanged_and_fails_a_regression(n2r_project, monkeypatch):
    n2r_project.write(GATED)
    base = n2r_project.pytester.path / "baseline.json"
    saved = n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", str(base))
    saved.assert_outcomes(passed=1)
    (relation,) = json.loads(base.read_text())["relations"].values()
    accepted = [e for e in relation["examples"] if e["status"] == "accepted"]
    assert len(accepted) == 12 and relation["eps"] == 1000 and relation["scene_hash"]
    assert all(len(e["source_c2w"]) == 16 and e["camera"]["width"] == 96 for e in relation["examples"])

    same = n2r_project.run(*DERANDOMIZED, "--n2r-compare", str(base), "--n2r-json", "same.json")
    assert same.ret == 0, same.stdout.str()
    gate = json.loads((n2r_project.pytester.path / "same.json").read_text())["comparison"]
    assert gate["passed"] is True and gate["failed"] == [] and gate["baseline"] == str(base), gate
    (outcome,) = gate["relations"]
    assert (outcome["nodeid"], outcome["verdict"], outcome["n"], outcome["bound"]) == \
        ("test_relations.py::test_brightness[plane]", "ok", 12, 0.0), outcome
    assert _row(same, "test_brightness[plane]")[1:] == ["12", "+0.0000", "+0.0000", "ok"]
    replayed = _json(n2r_project, "same.json")["test_brightness[plane]"]["replayed"]
    assert [(e["view"], e["transform"], e["deviation"]) for e in replayed] == \
        [(e["view"], e["transform"], e["deviation"]) for e in accepted], "exactly the baseline's examples, bit for bit"

    monkeypatch.setenv("N2R_CANDIDATE", "1")
    before = base.read_text()
    worse = n2r_project.run(*DERANDOMIZED, "--n2r-compare", str(base), "--n2r-compare-fail", "mean:0.02",
                            "--n2r-save-baseline", str(base), "--n2r-json", "worse.json")
    worse.assert_outcomes(passed=1)  # the relation itself holds (eps is huge) ...
    assert worse.ret == pytest.ExitCode.TESTS_FAILED, "... but the gate must fail the run"
    row = _row(worse, "test_brightness[plane]")
    assert row[1] == "12" and float(row[3]) > 0.02 and row[4] == "worse (fails)", row
    worse.stdout.fnmatch_lines(["*1 relation(s) fail the baseline comparison: *test_brightness[[]plane[]] (worse)*"])
    # refreshing the baseline in place must not replace it with the regressed run (the next comparison would pass)
    assert base.read_text() == before, "the baseline compared with was overwritten by a run that failed the gate"
    kept = (f"*pytest-n2r did not save the baseline {base}: it is the baseline this run compared with "
            "(--n2r-compare), and 1 relation(s) failed the comparison*")
    worse.stdout.fnmatch_lines([kept])
    gate = json.loads((n2r_project.pytester.path / "worse.json").read_text())["comparison"]
    assert gate["passed"] is False and gate["failed"] == ["test_relations.py::test_brightness[plane]"], gate
    assert gate["relations"][0]["verdict"] == "worse" and gate["relations"][0]["fails"] is True, gate


def test_the_replay_does_not_depend_on_the_search(n2r_project):
    """A baseline recorded with derandomized search is replayed exactly by a randomized run, and a run at
    another render size (the recorded camera is used)."""
    n2r_project.write(GATED)
    base = n2r_project.pytester.path / "baseline.json"
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", str(base)).assert_outcomes(passed=1)
    other = n2r_project.run("--n2r-scene", PLANE, "--n2r-derandomize", "no", "--n2r-size", "64",
                            "--n2r-compare", str(base))
    assert other.ret == 0, other.stdout.str()
    assert _row(other, "test_brightness[plane]")[1:] == ["12", "+0.0000", "+0.0000", "ok"]
    other.stdout.fnmatch_lines([
        f"baseline {base}: the same examples replayed and paired; *",
        ("baseline saved 20??-??-??T??:??:??Z by pytest-n2r * (rootdir *, config file *); render size *, "
        "--n2r-examples default *, derandomize yes, scenes plane"),
        ("note: this run's settings differ from the baseline's: render size 64 (baseline: *); derandomize no "
        "(baseline: yes). The replay uses the baseline's recorded cameras, poses and follow-ups, so each paired "
        "example is the baseline's own; this run's settings apply to its search only*")])


EMPTY = """
from pytest_n2r.metrics import repeatability


@metamorphic(repeatability(px=2), eps=1.0, transform=transforms(yaw=3), examples=8)
def test_keypoints(n2r_scene):
    if os.environ.get("N2R_CANDIDATE"):
        return lambda rgb: np.zeros((0, 2))  # the candidate detector finds nothing
    return grid
"""


def test_outcomes_of_the_comparison_and_their_rules(n2r_project, monkeypatch):
    n2r_project.write(GATED + EMPTY + """

def grid(rgb):
    h, w = rgb.shape[:2]
    u, v = np.meshgrid(np.arange(6, w, 16.0), np.arange(6, h, 16.0))
    return np.stack([u.ravel(), v.ravel()], axis=1)
""")
    base = str(n2r_project.pytester.path / "baseline.json")
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", base).assert_outcomes(passed=2)

    monkeypatch.setenv("N2R_CANDIDATE", "1")  # the empty detector fails its relation AND the gate
    empty = n2r_project.run(*DERANDOMIZED, "--n2r-compare", base)
    empty.assert_outcomes(failed=1, passed=1)
    assert _row(empty, "test_keypoints[plane]")[-1] == "no-pairs (fails)"
    empty.stdout.fnmatch_lines(["*test_keypoints[[]plane[]]: no-pairs: no paired example is a test now (8 of 8*"])
    monkeypatch.delenv("N2R_CANDIDATE")

    missing = n2r_project.run(*DERANDOMIZED, "--n2r-compare", base, "-k", "brightness")
    assert missing.ret == pytest.ExitCode.TESTS_FAILED
    missing.stdout.fnmatch_lines([("*test_keypoints[[]plane[]]: missing: in the baseline but not run in this session: "
                                  "collected, then deselected (-k / -m / --deselect) or skipped; run it, or pass "
                                  "--n2r-compare-fail-on without 'missing'")])
    allowed = n2r_project.run(*DERANDOMIZED, "--n2r-compare", base, "-k", "brightness",
                              "--n2r-compare-fail-on", "worse,changed-scene")
    assert allowed.ret == 0, allowed.stdout.str()

    other_scene = n2r_project.run("--n2r-scene", "tests.plugin.fakescene:ramp", "--n2r-derandomize", "yes",
                                  "--n2r-compare", base)
    assert other_scene.ret == pytest.ExitCode.TESTS_FAILED
    other_scene.stdout.fnmatch_lines([
        ("note: this run's settings differ from the baseline's: scenes ramp (baseline: plane). The replay uses the "
        "baseline's recorded cameras*"),
        "*test_brightness[[]ramp[]] *new*", "*test_brightness[[]plane[]] *missing (fails)*",
        ("*test_brightness[[]ramp[]]: new: not in the baseline: it runs on scene 'ramp', which the baseline's scenes "
        "(plane) lack: the scene set differs from the baseline's*"),
        ("*test_brightness[[]plane[]]: missing: in the baseline but not run: it was recorded on scene 'plane', which "
        "is not among this run's scenes (ramp): the scene set differs from the baseline's*")])

    n2r_project.write(GATED.replace("def test_brightness", "def test_lightness") + EMPTY + """

def grid(rgb):
    h, w = rgb.shape[:2]
    u, v = np.meshgrid(np.arange(6, w, 16.0), np.arange(6, h, 16.0))
    return np.stack([u.ravel(), v.ravel()], axis=1)
""")
    renamed = n2r_project.run(*DERANDOMIZED, "--n2r-compare", base)
    assert renamed.ret == pytest.ExitCode.TESTS_FAILED
    renamed.stdout.fnmatch_lines([("*test_brightness[[]plane[]]: missing: in the baseline but no test of this id was "
                                  "collected in this session: the relation was renamed or deleted*")])

    n2r_project.write((GATED + EMPTY).replace("eps=1000", "eps=900") + """

def grid(rgb):
    h, w = rgb.shape[:2]
    u, v = np.meshgrid(np.arange(6, w, 16.0), np.arange(6, h, 16.0))
    return np.stack([u.ravel(), v.ravel()], axis=1)
""")
    eps = n2r_project.run(*DERANDOMIZED, "--n2r-compare", base)
    assert eps.ret == 0 and _row(eps, "test_brightness[plane]")[-1] == "changed-eps", "said once, on its own line"
    assert eps.stdout.str().count("eps changed") == 1, eps.stdout.str()
    eps.stdout.fnmatch_lines([("*test_brightness[[]plane[]]: changed-eps: eps changed from 1000 to 900 (within the "
                              "margin)")])


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d.update(relations={}), "has no relations: it would let every relation pass as new"),
    (lambda d: next(e for e in next(iter(d["relations"].values()))["examples"] if e["status"] == "accepted").update(
        deviation=None), "examples[[]*[]].deviation (an accepted example)=None; expected a finite number"),
    (lambda d: next(iter(d["relations"].values())).pop("examples"), "missing field 'examples'"),
    (lambda d: d.update(version=1), "format version 1"),
])
def test_bad_baselines_are_usage_errors_not_tracebacks(n2r_project, edit, message):
    n2r_project.write(GATED)
    base = n2r_project.pytester.path / "baseline.json"
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", str(base)).assert_outcomes(passed=1)
    data = json.loads(base.read_text())
    edit(data)
    base.write_text(json.dumps(data))
    result = n2r_project.run(*DERANDOMIZED, "--n2r-compare", str(base))
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines([f"*pytest-n2r: baseline {base}*{message}*"])
    assert "Traceback" not in result.stderr.str() + result.stdout.str()


def test_the_gate_replays_under_xdist(n2r_project):
    pytest.importorskip("xdist")
    n2r_project.write(GATED)
    base = str(n2r_project.pytester.path / "baseline.json")
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", base).assert_outcomes(passed=1)
    result = n2r_project.run(*DERANDOMIZED, "--n2r-compare", base, "-n", "2", "-p", "no:benchmark")
    assert result.ret == 0 and _row(result, "test_brightness[plane]")[1:] == ["12", "+0.0000", "+0.0000", "ok"]


def test_missing_baseline_and_bad_rules_are_usage_errors(n2r_project):
    n2r_project.write(GATED)
    missing = n2r_project.run("--n2r-scene", PLANE, "--n2r-compare", "nope.json")
    assert missing.ret == pytest.ExitCode.USAGE_ERROR
    missing.stderr.fnmatch_lines(["*baseline nope.json does not exist; create it with --n2r-save-baseline*"])
    (n2r_project.pytester.path / "sub").mkdir()
    folder = n2r_project.run("--n2r-scene", PLANE, "--n2r-compare=sub")
    assert folder.ret == pytest.ExitCode.USAGE_ERROR
    folder.stderr.fnmatch_lines([("*pytest-n2r: baseline sub is a folder; expected a baseline file (the JSON file that "
                                 "--n2r-save-baseline PATH writes, e.g. sub/n2r-baseline.json)")])
    (n2r_project.pytester.path / "base.json").write_text("{}")
    empty = n2r_project.run("--n2r-scene", PLANE, "--n2r-compare", "base.json", "--n2r-compare-fail-on=")
    assert empty.ret == pytest.ExitCode.USAGE_ERROR
    empty.stderr.fnmatch_lines([("*pytest-n2r: --n2r-compare-fail-on='' names no outcome; give one or more of worse, "
                                "lost, *, comma-separated (default: worse, *)")])
    for flag, value in (("--n2r-compare-fail", "mean:0.1"), ("--n2r-compare-confidence", "0.9"),
                        ("--n2r-compare-fail-on", "new")):
        alone = n2r_project.run("--n2r-scene", PLANE, flag, value)
        assert alone.ret == pytest.ExitCode.USAGE_ERROR
        alone.stderr.fnmatch_lines([f"*{flag} needs --n2r-compare*"])


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
    assert props[("test_brightness[ramp]", "n2r_examples")] == str(sum(
        e["status"] == "accepted" for e in brightness["examples"]))
    rejected = sum(e["status"] == "rejected" for e in records["test_heading[ramp]"]["examples"])
    assert rejected > 0 and props[("test_heading[ramp]", "n2r_rejected")] == str(rejected)
    row = re.search(r"test_heading\[ramp\]</a></td>(.*?)</tr>", page).group(1)
    assert re.findall(r"<td[^>]*>(.*?)</td>", row)[2] == str(rejected), "the HTML rejected column counts them"
    assert props[("test_heading[ramp]", "n2r_inconsistencies")] != "0"


DARKENING = DARKEN + """

@metamorphic(AbsDifference(), eps=1000, transform=st.integers(1, 50).map(lambda k: Darken(k / 100)), examples=6)
def test_darkening(n2r_scene):
    return mean_colour
"""


def test_a_baseline_replays_a_mutation_class_defined_in_the_test_module(n2r_project, monkeypatch):
    """The baseline is read when the session starts, before any test module is imported: a mutation class of a
    test module is not registered yet then, and the baseline was refused as naming an unknown mutation."""
    from pytest_n2r.strategies import mutation

    n2r_project.write(DARKENING)
    base = n2r_project.pytester.path / "baseline.json"
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", str(base)).assert_outcomes(passed=1)
    monkeypatch.delitem(mutation._KINDS, "darken")  # as in a new process: the test module not imported yet
    same = n2r_project.run(*DERANDOMIZED, "--n2r-compare", str(base), "--n2r-json", "same.json")
    assert same.ret == 0, same.stdout.str() + same.stderr.str()
    assert _row(same, "test_darkening[plane]")[1:] == ["6", "+0.0000", "+0.0000", "ok"]
    assert len(_json(n2r_project, "same.json")["test_darkening[plane]"]["replayed"]) == 6


def test_a_baseline_mutation_no_module_defines_is_an_error_naming_it(n2r_project, monkeypatch):
    from pytest_n2r.strategies import mutation

    n2r_project.write(DARKENING)
    base = n2r_project.pytester.path / "baseline.json"
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", str(base)).assert_outcomes(passed=1)
    monkeypatch.delitem(mutation._KINDS, "darken")
    n2r_project.write(DARKENING.replace('"darken"', '"darker"'))  # the class was renamed since the baseline
    renamed = n2r_project.run(*DERANDOMIZED, "--n2r-compare", str(base))
    assert renamed.ret != 0
    renamed.stdout.fnmatch_lines(["*test_darkening*name mutation(s) [[]'darken'[]] that no imported module defines*"])


def test_a_comparison_from_another_rootdir_says_so(n2r_project):
    """A baseline records pytest's rootdir from its own folder: the same on every clone, and a run whose rootdir
    differs (its test ids differ: every relation "missing") is told which rootdir the baseline was saved with."""
    n2r_project.write(GATED)
    (n2r_project.pytester.path / "gate").mkdir()
    base = n2r_project.pytester.path / "gate" / "baseline.json"
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline", str(base)).assert_outcomes(passed=1)
    meta = json.loads(base.read_text())["meta"]
    assert (meta["rootdir"], meta["config_file"]) == ("..", None), meta
    same = n2r_project.run(*DERANDOMIZED, "--n2r-compare", str(base))
    assert same.ret == 0 and "rootdir (from the baseline's folder)" in same.stdout.str(), same.stdout.str()
    assert "settings differ" not in same.stdout.str(), same.stdout.str()
    moved = n2r_project.run(*DERANDOMIZED, f"--rootdir={base.parent}", "--n2r-compare", str(base))
    moved.stdout.fnmatch_lines([("note: this run's settings differ from the baseline's: rootdir (from the "
                                 "baseline's folder) . (baseline: ..)*")])


def test_a_passing_comparison_may_refresh_its_baseline_in_place(n2r_project):
    """--n2r-save-baseline onto the --n2r-compare file is refused only after a failing gate."""
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=4), examples=6)
def test_mean_colour(n2r_scene):
    return mean_colour
""")
    derandomized = ("--n2r-scene", "tests.plugin.fakescene:plane", "--n2r-derandomize", "yes")
    n2r_project.run(*derandomized, "--n2r-save-baseline=b.json").assert_outcomes(passed=1)
    again = n2r_project.run(*derandomized, "--n2r-compare=b.json", "--n2r-save-baseline=b.json")
    assert again.ret == pytest.ExitCode.OK, again.stdout.str()
    assert "did not save the baseline" not in again.stdout.str()


def test_a_baseline_is_replayed_only_under_the_metric_it_was_saved_with(n2r_project):
    """``--n2r-compare`` replays a relation's baseline examples before its search; once the test's metric changed,
    those examples measured something else, so they are not replayed (the comparison reports the change)."""
    n2r_project.write("""
@metamorphic(AbsDifference(), eps=1000, transform=transforms(yaw=4), examples=6)
def test_turn(n2r_scene):
    return mean_colour
""")
    n2r_project.run(*DERANDOMIZED, "--n2r-save-baseline=b.json").assert_outcomes(passed=1)
    same = n2r_project.run(*DERANDOMIZED, "--n2r-compare=b.json")
    assert "baseline examples replayed" in n2r_project.summary(same, "test_turn[plane]"), same.stdout.str()
    n2r_project.write("""
@metamorphic(SameLabel(), eps=0.5, transform=transforms(yaw=4), examples=6)
def test_turn(n2r_scene):
    return heading_class
""")
    changed = n2r_project.run(*DERANDOMIZED, "--n2r-compare=b.json")
    assert "baseline examples replayed" not in n2r_project.summary(changed, "test_turn[plane]"), \
        changed.stdout.str()
