"""Baselines round-trip with everything a replay needs, are validated on load (every field, every number),
and compare the same examples in pairs with an explicit outcome for every case."""

from __future__ import annotations

import copy
import json
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pytest_n2r
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.report import (
    BaselineError,
    ExampleRecord,
    RelationRecord,
    compare_paired,
    load_baseline,
    parse_margin,
    parse_outcomes,
    replay_candidates,
    save_baseline,
)
from pytest_n2r.report.baseline import Baseline, describe_baseline, setting_differences
from pytest_n2r.report.compare import DEFAULT_FAIL_ON, format_comparison_table, paired_bound

CAMERA = {"width": 320, "height": 180, "fx": 250.0, "fy": 250.0, "cx": 159.5, "cy": 89.5, "distortion": []}
POSE = [1.0, 0, 0, 0.5, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]


def _example(i: int, deviation: float, eps: float = 0.2, status: str = "accepted") -> ExampleRecord:
    ok = status == "accepted"
    return ExampleRecord("wall", f"view{i % 3}", {"roll": 0.0, "pitch": 0.0, "yaw": float(i), "x": 0.0, "y": 0.0,
                                                  "z": 0.0},
                         1.0 - deviation if ok else math.nan, deviation if ok else math.nan, ok and deviation <= eps,
                         status=status, reason="" if ok else "no keypoint", scene_hash="abc",
                         source_c2w=list(POSE), camera=dict(CAMERA))


def _relation(nodeid: str, deviations: list[float], eps: float = 0.2, metric: str = "repeatability(px=2.0)",
              scene_hash: str = "abc", statuses: list[str] | None = None) -> RelationRecord:
    statuses = statuses or ["accepted"] * len(deviations)
    examples = [_example(i, d, eps, s) for i, (d, s) in enumerate(zip(deviations, statuses))]
    return RelationRecord(nodeid, metric, eps, examples, scene="wall", scene_hash=scene_hash)


def _replayed(base: RelationRecord, deviations: list[float], statuses: list[str] | None = None,
              **changes) -> RelationRecord:
    """The current run of ``base``: its replayed examples got ``deviations``."""
    cur = _relation(base.nodeid, [e.deviation for e in base.examples], **changes)
    statuses = statuses or ["accepted"] * len(deviations)
    cur.replayed = [_example(i, d, cur.eps, s) for i, (d, s) in enumerate(zip(deviations, statuses))]
    return cur


def test_round_trip_keeps_every_example_and_its_replay_data(tmp_path):
    rel = _relation("t.py::test_orb", [0.0, 0.1, 0.3, 0.0], statuses=["accepted", "accepted", "accepted", "undefined"])
    path = save_baseline(tmp_path / "base.json", [rel], meta={"scene": "wall"})
    loaded = load_baseline(path)["t.py::test_orb"]
    assert [e.key() for e in loaded.examples] == [e.key() for e in rel.examples]
    assert [e.status for e in loaded.examples] == ["accepted", "accepted", "accepted", "undefined"]
    assert [e.deviation for e in loaded.examples[:3]] == [0.0, 0.1, 0.3] and math.isnan(loaded.examples[3].deviation)
    assert loaded.examples[0].source_c2w == POSE and loaded.examples[0].camera == CAMERA
    assert loaded.scene_hash == "abc" and loaded.eps == 0.2
    assert "NaN" not in path.read_text(), "a baseline is strict JSON: no value is written null"
    assert [e.view for e in replay_candidates(loaded)] == ["view0", "view1", "view2"], "only tests are replayed"


def test_baseline_file_is_stable_and_sorted(tmp_path):
    rels = [_relation("b::t", [0.1]), _relation("a::t", [0.2])]
    meta = {"saved": "2024-12-07T03:20:11Z"}  # else a second may pass between the two
    first = save_baseline(tmp_path / "1.json", rels, meta=meta).read_text()
    second = save_baseline(tmp_path / "2.json", list(reversed(rels)), meta=meta).read_text()
    assert first == second, "the baseline must not depend on the order relations ran in"
    assert list(json.loads(first)["relations"]) == ["a::t", "b::t"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["1.json", "2.json"], "no temporary file left behind"


def _valid_data(tmp_path) -> dict:
    return json.loads(save_baseline(tmp_path / "good.json", [_relation("a::t", [0.1, 0.2])]).read_text())


def _set(data: dict, path: str, value) -> dict:
    data = copy.deepcopy(data)
    *parents, last = path.split("/")
    node = data
    for key in parents:
        node = node[int(key)] if key.isdigit() else node[key]
    if value is _DELETE:
        del node[last]
    else:
        node[int(last) if last.isdigit() else last] = value
    return data


_DELETE = object()
_EX = "relations/a::t/examples/0"


@pytest.mark.parametrize(("path", "value", "expected"), [
    ("relations", {}, "has no relations: it would let every relation pass as new"),
    ("relations", [], "has no relations"),
    ("version", 1, "format version 1; this pytest-n2r reads version 2 \\(paired replay\\)"),
    ("relations/a::t/eps", -1, "relation 'a::t': eps=-1; expected a number >= 0"),
    ("relations/a::t/eps", "0.2", "eps='0.2'; expected a finite number"),
    ("relations/a::t/eps", 10**400, r"eps=10{400}; expected a finite number"),  # float() would overflow
    ("relations/a::t/scene_hash", _DELETE, "missing field 'scene_hash'"),
    ("relations/a::t/examples", {}, "examples=dict; expected a list"),
    (f"{_EX}/deviation", None, r"examples\[0\].deviation \(an accepted example\)=None; expected a finite number"),
    (f"{_EX}/deviation", -0.5, r"deviation \(an accepted example\)=-0.5; expected a number >= 0"),
    (f"{_EX}/score", 1e999, r"not readable JSON: Infinity is not a number JSON allows"),
    (f"{_EX}/score", True, r"examples\[0\].score=True; expected a finite number"),
    (f"{_EX}/status", "maybe", r"examples\[0\].status='maybe'; expected one of"),
    (f"{_EX}/source_c2w", [1, 2], r"examples\[0\].source_c2w must be 16 numbers"),
    (f"{_EX}/camera/width", 0, r"examples\[0\].camera.width=0; expected a whole number of pixels"),
    (f"{_EX}/camera/fx", "x", r"examples\[0\].camera.fx='x'"),
    (f"{_EX}/transform", {"yaw": 1, "spin": 2}, r"examples\[0\].transform=.*expected an object with fields"),
    (f"{_EX}/transform", None, r"examples\[0\] has neither a transform nor a mutation"),
    (f"{_EX}/passed", "yes", r"examples\[0\].passed='yes'; expected true or false"),
    (f"{_EX}/units", "feet", r"units='feet'"),
    # (a name no imported module defines is kept until the replay: tests/plugin/test_reporting.py)
    (f"{_EX}/mutation", {"name": "brightness", "blur": 3},
     r"examples\[0\].mutation: .*has no parameter\(s\) \['blur'\]"),
    ("relations/a::t/examples/0", 3, r"examples\[0\] is int; expected an example object"),
    # each of these once ended in a TypeError from ExampleRecord or Camera, or loaded and was silently dropped
    (f"{_EX}/scene", _DELETE, r"relation 'a::t': examples\[0\] is missing the field 'scene'"),
    (f"{_EX}/scene", 3, r"relation 'a::t': examples\[0\].scene=3; expected a string"),
    (f"{_EX}/transform", _DELETE, r"examples\[0\] is missing the field 'transform' \(an object with fields"),
    (f"{_EX}/camera/distortion", 5, r"examples\[0\].camera.distortion=5; expected a list of 0, 4, 5 or 8 numbers"),
    (f"{_EX}/camera/distortion", [0.1, "k2", 0, 0], r"examples\[0\].camera.distortion\[1\]='k2'; expected a finite"),
    (f"{_EX}/settings", [1, 2], r"examples\[0\].settings=\[1, 2\]; expected an object"),
    (f"{_EX}/reason", 7, r"examples\[0\].reason=7; expected a string"),
    (f"{_EX}/mutation", {"name": "brightness", "levels": 3}, r"examples\[0\] has both a transform and a mutation"),
    ("meta", {"not_recorded": "a::u"}, r"meta.not_recorded='a::u'; expected a list of test ids"),
    # a version that is not an integer once read "has format version '2'; this pytest-n2r reads version 2"
    ("version", "2", (r"has \"version\": '2' \(str\); expected an integer, the format version \(this "
                      r"pytest-n2r reads 2\)")),
    ("version", _DELETE, r"has no \"version\"; expected the integer 2"),
    # a misspelt field once passed silently (the record took its default)
    (f"{_EX}/devation", 0.1, (r"relation 'a::t': examples\[0\]: unknown field\(s\) \['devation'\] \(misspelt\?\); "
                              r"expected fields of \[.*'deviation'")),
    ("relations/a::t/espilon", 0.1, (r"relation 'a::t': unknown field\(s\) \['espilon'\] \(misspelt\?\); "
                                     r"expected fields of \['metric', 'eps'")),
])
def test_every_field_of_a_baseline_is_validated_on_load(tmp_path, path, value, expected):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(_set(_valid_data(tmp_path), path, value)))
    with pytest.raises(BaselineError, match=expected) as info:
        load_baseline(bad)
    assert str(bad) in str(info.value) and f"regenerate it with --n2r-save-baseline {bad}" in str(info.value)


@pytest.mark.parametrize("version", [3, 10])
def test_a_baseline_of_a_newer_format_says_to_upgrade_not_to_regenerate(tmp_path, version):
    """Saving the baseline again on a pull request would compare the candidate with itself."""
    newer = tmp_path / "newer.json"
    newer.write_text(json.dumps(_set(_valid_data(tmp_path), "version", version)))
    with pytest.raises(BaselineError) as info:
        load_baseline(newer)
    assert str(info.value) == (
        f"baseline {newer} has format version {version}; this pytest-n2r reads version 2: it was written by a newer "
        "pytest-n2r; upgrade pytest-n2r to read it (do not save it again with this one: on a pull request that "
        "would compare the candidate with itself)")


@pytest.mark.parametrize(("twice", "where"), [("a::t", "relations"), ("eps", "relations['a::t']"),
                                              ("deviation", "relations['a::t'].examples[0]"),
                                              ("version", "the top-level object")])
def test_a_key_given_twice_is_refused_naming_it_and_where(tmp_path, twice, where):
    """JSON readers keep the last of two equal keys: a hand-merged baseline silently lost a relation (or a value)."""
    data = _valid_data(tmp_path)
    text = json.dumps(data)
    if twice == "a::t":  # a second entry of the relation, before the first
        again = '"relations": {"a::t": ' + json.dumps(data["relations"]["a::t"]) + ", "
        text = text.replace('"relations": {', again, 1)
    else:
        text = text.replace(f'"{twice}": ', f'"{twice}": 0.5, "{twice}": ', 1)
    json.loads(text)  # still JSON a reader takes, keeping the last
    dup = tmp_path / "dup.json"
    dup.write_text(text)
    with pytest.raises(BaselineError) as info:
        load_baseline(dup)
    # where it sits too: "one object" did not say which of a baseline's hundreds
    assert str(info.value) == (f"baseline {dup}: the key {twice!r} appears twice in {where} (a JSON reader keeps only "
                               "the last and drops the other without a word: a hand edit or a merge?); keep one of "
                               f"them, or regenerate it with --n2r-save-baseline {dup}")


@pytest.mark.parametrize(("content", "expected"), [
    (None, "does not exist; create it with --n2r-save-baseline"),
    ("{not json", "not readable JSON"),
    ('{"format": "pytest-n2r-baseline", "version": 2, "relations": {"a": {"eps": NaN}}}',
     "NaN is not a number JSON allows"),
    ('{"format": "other"}', "is not a pytest-n2r baseline"),
    ("[1, 2]", "is not a pytest-n2r baseline"),
    ('{"format": "pytest-n2r-baseline", "version": 2, "relations": ' + "[" * 100000 + "]" * 100000 + "}",
     "not readable JSON: nested too deeply for the JSON parser; regenerate it"),
])
def test_unreadable_baseline_files_say_what_is_wrong(tmp_path, content, expected):
    path = tmp_path / "base.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(BaselineError, match=expected) as info:
        load_baseline(path)
    assert str(path) in str(info.value)


def test_identical_replays_are_ok_with_a_bound_of_exactly_zero():
    base = _relation("a::t", [0.1, 0.3, 0.0, 0.25] * 5)
    (c,) = compare_paired({"a::t": base}, [_replayed(base, [e.deviation for e in base.examples])])
    assert (c.outcome, c.n, c.mean_change, c.bound, c.fails) == ("ok", 20, 0.0, 0.0, False)


def test_a_paired_increase_beyond_the_margin_is_worse_and_fails():
    base = _relation("a::t", [0.1, 0.3, 0.0, 0.25] * 5)
    (c,) = compare_paired({"a::t": base}, [_replayed(base, [e.deviation + 0.08 for e in base.examples])], margin=0.02)
    assert c.outcome == "worse" and c.fails and c.bound == pytest.approx(0.08) and c.n == 20
    assert "lower bound +0.0800 exceeds the margin 0.02" in c.message


def test_pairing_sees_a_shift_that_summary_statistics_cannot():
    """Each example gets 0.05 worse while the spread of deviations hides it from unpaired statistics."""
    devs = [0.05 * i for i in range(20)]
    base = _relation("a::t", devs)
    (c,) = compare_paired({"a::t": base}, [_replayed(base, [d + 0.05 for d in devs])], margin=0.02)
    assert c.outcome == "worse"
    (noisy,) = compare_paired({"a::t": base}, [_replayed(base, [d + (0.05 if i % 2 else -0.05)
                                                                for i, d in enumerate(devs)])], margin=0.02)
    assert noisy.outcome == "ok", "changes that cancel out in pairs are no regression"


@pytest.mark.parametrize(("base_kw", "cur_kw", "outcome", "fails", "message"), [
    ({}, {"metric": "repeatability(px=3.0)"}, "changed-metric", True, "metric changed from"),
    ({}, {"scene_hash": "def"}, "changed-scene", True, "recorded on scene content abc, run on def"),
    ({}, {"eps": 0.3}, "changed-eps", False, "eps changed from 0.2 to 0.3"),
])
def test_changed_metric_scene_and_eps_are_explicit_outcomes(base_kw, cur_kw, outcome, fails, message):
    base = _relation("a::t", [0.1] * 10, **base_kw)
    (c,) = compare_paired({"a::t": base}, [_replayed(base, [0.1] * 10, **cur_kw)])
    assert (c.outcome, c.fails) == (outcome, fails) and message in c.message, c


def test_missing_new_and_unreplayed_relations_are_explicit_outcomes():
    base = {"a::t": _relation("a::t", [0.1] * 5), "gone::t": _relation("gone::t", [0.1] * 5)}
    errored = _relation("a::t", [])
    errored.outcome = "error"
    result = {c.nodeid: c for c in compare_paired(base, [errored, _relation("new::t", [0.1])])}
    assert (result["gone::t"].outcome, result["gone::t"].fails) == ("missing", True)
    assert (result["new::t"].outcome, result["new::t"].fails) == ("new", False)
    assert (result["a::t"].outcome, result["a::t"].fails) == ("no-pairs", True)
    assert "the relation ended in error" in result["a::t"].message
    table = format_comparison_table(list(result.values()))
    assert "missing (fails)" in table and "no-pairs (fails)" in table


def test_examples_that_became_undefined_are_lost_and_fail():
    """An empty detector makes every example undefined: the gate fails, it does not pass as 'new' or 'ok'."""
    base = _relation("a::t", [0.1] * 10)
    (empty,) = compare_paired({"a::t": base}, [_replayed(base, [0.0] * 10, statuses=["undefined"] * 10)])
    assert (empty.outcome, empty.fails) == ("no-pairs", True) and "0 paired" not in empty.message
    (some,) = compare_paired({"a::t": base}, [_replayed(base, [0.1] * 10, statuses=["undefined"] * 2
                                                        + ["accepted"] * 8)])
    assert (some.outcome, some.lost, some.fails) == ("lost", 2, True)


def test_fail_on_chooses_which_outcomes_fail():
    base = {"gone::t": _relation("gone::t", [0.1])}
    (c,) = compare_paired(base, [], fail_on=("worse",))
    assert c.outcome == "missing" and not c.fails
    assert parse_outcomes(None) == DEFAULT_FAIL_ON and parse_outcomes("new,changed-eps") == ("new", "changed-eps")
    with pytest.raises(InvalidArgument, match="unknown outcome"):
        parse_outcomes("worse,bad")


@pytest.mark.parametrize("spec", ["p90:0.1", "mean", "mean:x", "mean:0.1,mean:0.2"])
def test_bad_margin_specs_name_the_option(spec):
    with pytest.raises(InvalidArgument, match="--n2r-compare-fail"):
        parse_margin(spec)


def test_margin_default_and_value():
    assert parse_margin(None) == 0.02 and parse_margin(["mean:0.05"]) == 0.05


@settings(deadline=None)  # the first example imports scipy.stats (0.3-0.5 s) when this file runs alone
@given(st.lists(st.floats(-1, 1), min_size=2, max_size=60))
def test_the_bound_is_below_the_mean_and_deterministic(changes):
    bound = paired_bound(changes)
    assert bound <= sum(changes) / len(changes) + 1e-12 and bound == paired_bound(changes)


def test_the_bound_of_nothing_is_nan():
    assert math.isnan(paired_bound([])) and math.isnan(paired_bound([math.nan, 0.1]))


def test_replayed_examples_that_are_not_the_baselines_are_not_paired():
    base = _relation("a::t", [0.1] * 5)
    cur = _replayed(base, [0.1] * 5)
    cur.replayed[2].transform = {**cur.replayed[2].transform, "yaw": 33.0}
    (c,) = compare_paired({"a::t": base}, [cur])
    assert (c.outcome, c.fails) == ("no-pairs", True) and "are not the baseline's" in c.message


def test_a_mutation_without_a_name_is_refused_not_dropped(tmp_path):
    """An accepted example whose mutation has no ``name`` (and no transform) cannot be replayed: refused on load,
    where it once loaded and was left out of the replay without a word."""
    data = _valid_data(tmp_path)
    data = _set(_set(data, f"{_EX}/transform", None), f"{_EX}/mutation", {"levels": 30})
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    with pytest.raises(BaselineError, match=r"relation 'a::t': examples\[0\].mutation=\{'levels': 30\}; expected an "
                                            r"object with the mutation's 'name'") as info:
        load_baseline(bad)
    assert str(bad) in str(info.value), f"the file is not named: {info.value}"


def test_follow_ups_with_fields_left_out_still_pair_with_their_replay(tmp_path):
    """A transform written with some of its six fields (those that are 0 left out) and a mutation written with
    some of its parameters (the defaults left out) pair with the replay, which records them all."""
    base = _relation("a::t", [0.1, 0.2])
    mutated = ExampleRecord("wall", "view0", None, 0.9, 0.1, True, scene_hash="abc", source_c2w=list(POSE),
                            camera=dict(CAMERA), mutation={"name": "brightness", "levels": 0})
    base.examples.append(mutated)
    data = json.loads(save_baseline(tmp_path / "full.json", [base]).read_text())
    for e in data["relations"]["a::t"]["examples"]:
        if e["transform"] is not None:
            e["transform"] = {k: v for k, v in e["transform"].items() if v}
        else:
            e["mutation"] = {"name": "brightness"}
    short = tmp_path / "short.json"
    short.write_text(json.dumps(data))
    loaded = load_baseline(short)
    cur = _replayed(base, [0.1, 0.2])
    cur.replayed.append(mutated)
    (result,) = compare_paired(loaded, [cur])
    assert (result.outcome, result.n) == ("ok", 3), (
        f"examples with fields left out did not pair with their replay: {result.outcome} ({result.message})")


def test_relations_the_saving_session_did_not_run_are_missing_not_new(tmp_path):
    """A baseline saved from a session that deselected a relation (``-k``) lists it in ``meta.not_recorded``; a
    later run of that relation has nothing to compare with, and says so as a failing ``missing``, not ``new``."""
    path = save_baseline(tmp_path / "b.json", [_relation("a::t", [0.1])], meta={"not_recorded": ["a::u"]})
    loaded = load_baseline(path)
    by_id = {c.nodeid: c for c in compare_paired(loaded, [_replayed(loaded["a::t"], [0.1]),
                                                          _relation("a::u", [0.1]), _relation("a::v", [0.1])])}
    assert by_id["a::u"].outcome == "missing" and by_id["a::u"].fails, (
        f"a relation deselected when the baseline was saved passed as {by_id['a::u'].outcome}")
    assert "deselected" in by_id["a::u"].message, by_id["a::u"].message
    assert by_id["a::v"].outcome == "new" and not by_id["a::v"].fails, "a relation added since stays new"


@pytest.mark.parametrize("changes", [[0.03, 0.05], [0.025, 0.03, 0.2], [0.1] * 10 + [0.0] * 10,
                                     list(np.linspace(-0.1, 0.3, 40))])
def test_the_bound_is_students_one_sided_t_bound(changes):
    """A percentile bootstrap called 24 % of 2-pair comparisons worse at a true mean equal to the margin (5 %
    asked): with 2 pairs its 5 % quantile is the smaller change."""
    from scipy import stats

    x = np.asarray(changes)
    expected = x.mean() - stats.t.ppf(0.95, x.size - 1) * x.std(ddof=1) / np.sqrt(x.size)
    assert paired_bound(changes) == pytest.approx(expected, rel=1e-12, abs=1e-15)
    assert paired_bound(changes, 0.99) < paired_bound(changes), "a higher confidence gives a lower bound"
    assert paired_bound([0.4]) == -math.inf, "one pair bounds nothing: it can never be worse"
    assert paired_bound([0.07] * 5) == 0.07, "identical changes: the bound is the change"


def test_the_bound_keeps_its_false_alarm_rate_with_few_pairs():
    """At a true mean change equal to the margin, a 95 % bound exceeds it in about 5 % of comparisons."""
    rng = np.random.default_rng(7)
    for n in (2, 3, 5, 20):
        alarms = sum(paired_bound(list(rng.normal(0.02, 0.05, n))) > 0.02 for _ in range(2000))
        assert 0.03 < alarms / 2000 < 0.07, f"{n} pairs: {alarms / 2000:.3f} false 'worse' verdicts, 0.05 asked"


def test_a_relation_both_lost_and_worse_fails_if_either_is_a_failing_outcome():
    """'lost' was decided first and alone: with --n2r-compare-fail-on worse,changed-scene a relation that lost 3
    of 20 examples and got +0.5 worse on the other 17 passed the gate."""
    base = _relation("a::t", [0.1] * 20)
    current = _replayed(base, [0.6] * 20, statuses=["undefined"] * 3 + ["accepted"] * 17)
    (c,) = compare_paired({"a::t": base}, [current], fail_on=("worse", "changed-scene"))
    assert (c.outcome, c.also, c.fails) == ("lost", ("worse",), True), c
    assert "also worse: the deviation grew by +0.5000" in c.message, c.message
    assert "lost+worse (fails)" in format_comparison_table([c]), "the table names every outcome that applies"


def test_a_single_pair_says_it_cannot_be_judged():
    base = _relation("a::t", [0.1])
    (c,) = compare_paired({"a::t": base}, [_replayed(base, [0.9])])
    assert c.outcome == "ok" and "1 pair: no confidence bound, so it cannot be judged worse" in c.notes, c


def test_a_clearly_better_candidate_is_told_to_refresh_the_baseline():
    """A candidate far better than the baseline showed only "ok": the baseline then gates against the old, worse
    detector until someone thinks of saving a new one."""
    base = _relation("a::t", [0.5 + 0.01 * (i % 3) for i in range(20)])
    (better,) = compare_paired({"a::t": base}, [_replayed(base, [0.2 + 0.01 * (i % 2) for i in range(20)])])
    assert better.outcome == "ok" and any(n.startswith("better: the deviation fell") for n in better.notes), better
    (same,) = compare_paired({"a::t": base}, [_replayed(base, [0.5 + 0.01 * (i % 3) for i in range(20)])])
    assert not any(n.startswith("better") for n in same.notes), same


def test_a_few_lost_examples_are_noted_beside_an_ok_verdict():
    """Up to 10 % of pairs may drop out, and they may be exactly the candidate's worst: the verdict says so."""
    base = _relation("a::t", [0.1] * 18 + [0.4, 0.45])
    current = _replayed(base, [0.1] * 18 + [0.9, 0.9], statuses=["accepted"] * 18 + ["undefined", "rejected"])
    (c,) = compare_paired({"a::t": base}, [current])
    assert (c.outcome, c.lost, c.fails) == ("ok", 2, False)
    assert c.notes == ["2 of 20 lost: undefined or rejected now, left out of the mean"], c.notes
    assert "2 of 20 lost" in format_comparison_table([c])


def test_the_confidence_is_checked_and_shown_to_its_last_digit():
    base = _relation("a::t", [0.1] * 5)
    for bad in (1.5, 0.3, 1.0):
        with pytest.raises(InvalidArgument, match=f"confidence={bad!r} is not a probability in"):
            compare_paired({"a::t": base}, [_replayed(base, [0.1] * 5)], confidence=bad)
    assert "97.5% lower bound" in format_comparison_table([], confidence=0.975)
    assert compare_paired({"a::t": base}, [_replayed(base, [0.1] * 5)], confidence=np.float32(0.9))[0].outcome == "ok"


def test_empty_fail_on_is_an_error_not_the_default():
    """``--n2r-compare-fail-on=`` silently meant the default set: it names no outcome, so it is refused."""
    for spec in ("", [""], " , ", ["", ","]):
        with pytest.raises(InvalidArgument) as info:
            parse_outcomes(spec)
        assert str(info.value).startswith("--n2r-compare-fail-on=") and "names no outcome; give one or more of " \
            "worse, lost, no-pairs, changed-scene, changed-metric, changed-eps, missing, new, comma-separated " \
            "(default: worse, lost, no-pairs, changed-scene, changed-metric, missing)" in str(info.value), info.value


def test_a_changed_eps_is_said_once():
    """The eps change was said twice: as a note in the verdict column and on the message line."""
    base = _relation("a::t", [0.1] * 10)
    (within,) = compare_paired({"a::t": base}, [_replayed(base, [0.1] * 10, eps=0.3)])
    assert within.notes == [] and within.message == "eps changed from 0.2 to 0.3 (within the margin)", within
    (worse,) = compare_paired({"a::t": base}, [_replayed(base, [0.5] * 10, eps=0.3)])
    assert worse.verdict == "worse+changed-eps" and worse.notes == [], worse
    assert worse.message.endswith("; also changed-eps: eps changed from 0.2 to 0.3"), worse.message
    assert "eps changed" not in format_comparison_table([within, worse])


def _on(scene: str, nodeid: str) -> RelationRecord:
    rel = _relation(nodeid, [0.1] * 3)
    rel.scene = scene
    return rel


def test_a_missing_relation_says_why_when_the_session_can_tell():
    base = {"m.py::test_a[wall]": _on("wall", "m.py::test_a[wall]"),
            "m.py::test_old[wall]": _on("wall", "m.py::test_old[wall]")}
    run = {"collected": {"m.py::test_a[wall]"}, "scenes": ["wall"]}
    by_id = {c.nodeid: c for c in compare_paired(base, [_on("wall", "m.py::test_new[wall]")], **run)}
    deselected, renamed = by_id["m.py::test_a[wall]"], by_id["m.py::test_old[wall]"]
    assert deselected.message == ("in the baseline but not run in this session: collected, then deselected (-k / -m / "
                                  "--deselect) or skipped; run it, or pass --n2r-compare-fail-on without 'missing'")
    assert renamed.message == (
        "in the baseline but no test of this id was collected in this session: the relation was renamed or deleted "
        "(or its file was not among the paths given to pytest); on a pull request that renames or removes a "
        "relation, refresh the baseline when it merges, or pass --n2r-compare-fail-on without 'missing' for that "
        "pull request (docs/reporting.md)")
    assert (deselected.outcome, renamed.outcome, by_id["m.py::test_new[wall]"].outcome) == ("missing", "missing", "new")

    by_id = {c.nodeid: c for c in compare_paired({"m.py::test_a[wall]": base["m.py::test_a[wall]"]},
                                                 [_on("ramp", "m.py::test_a[ramp]")],
                                                 collected={"m.py::test_a[ramp]"}, scenes=["ramp"])}
    assert by_id["m.py::test_a[wall]"].message == (
        "in the baseline but not run: it was recorded on scene 'wall', which is not among this run's scenes (ramp): "
        "the scene set differs from the baseline's; run with the baseline's scenes, save a new baseline on this "
        "scene set, or pass --n2r-compare-fail-on without 'missing'")
    assert by_id["m.py::test_a[ramp]"].message == (
        "not in the baseline: it runs on scene 'ramp', which the baseline's scenes (wall) lack: the scene set differs "
        "from the baseline's, so nothing to compare with (save a new baseline on this scene set to include it)")
    (unknown,) = compare_paired({"m.py::test_a[wall]": base["m.py::test_a[wall]"]}, [])
    assert "(deselected, renamed or deleted)" in unknown.message, "without the session's collection, all cases"


def test_a_baseline_records_where_it_came_from_and_old_ones_still_load(tmp_path):
    settings = {"rootdir": "/repo", "config_file": "/repo/pyproject.toml", "size": "96", "examples": 12,
                "derandomize": True, "scenes": ["plane"]}
    path = save_baseline(tmp_path / "b.json", [_relation("a::t", [0.1])], meta=settings)
    data = json.loads(path.read_text())
    assert data["version"] == 2 and data["meta"]["pytest_n2r"] == pytest_n2r.__version__
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", data["meta"]["saved"]), data["meta"]
    loaded = load_baseline(path)
    assert loaded.meta == {**settings, "pytest_n2r": pytest_n2r.__version__, "saved": data["meta"]["saved"]}
    assert describe_baseline(loaded.meta) == (
        f"baseline saved {data['meta']['saved']} by pytest-n2r {pytest_n2r.__version__} (rootdir /repo, "
        "config file /repo/pyproject.toml); render size 96, --n2r-examples default 12, derandomize yes, scenes plane")
    assert setting_differences(loaded.meta, {**settings, "size": "64", "scenes": ["plane", "wall"]}) == \
        ["render size 64 (baseline: 96)", "scenes plane, wall (baseline: plane)"]
    assert setting_differences(loaded.meta, {**settings, "scenes": ["plane"]}) == []

    data["meta"] = {}  # a baseline saved before pytest-n2r recorded where it came from
    path.write_text(json.dumps(data))
    old = load_baseline(path)
    assert old.meta == {} and setting_differences(old.meta, settings) == []
    assert describe_baseline(old.meta) == (
        "baseline saved by an older pytest-n2r, which did not record its version, date or settings")
    data["meta"] = {"examples": "12"}
    path.write_text(json.dumps(data))
    with pytest.raises(BaselineError, match=r"meta.examples='12'; expected a whole number; regenerate it"):
        load_baseline(path)


def test_meta_fields_are_defined_once():
    """Their names, types and meanings were written twice (baseline.py's META_FIELDS, validate.py's types)."""
    from pytest_n2r.report import baseline, validate

    assert not hasattr(baseline, "META_FIELDS"), "a second definition of the meta fields"
    assert set(validate.META_FIELDS) == {"not_recorded", "pytest_n2r", "saved", "rootdir", "config_file", "size",
                                         "examples", "derandomize", "scenes"}
    assert all(isinstance(what, str) and what for _, what, _ in validate.META_FIELDS.values())


def test_a_tilde_in_the_baseline_path_is_the_home_folder(tmp_path, monkeypatch):
    """``--n2r-compare=~/b.json``: no shell expands a ~ after '=', and the baseline was saved where ~ is."""
    monkeypatch.setenv("HOME", str(tmp_path))
    save_baseline(tmp_path / "b.json", [_relation("a::t", [0.1])])
    assert set(load_baseline("~/b.json")) == {"a::t"}
    with pytest.raises(BaselineError) as info:
        load_baseline("~/none.json")
    assert str(info.value).startswith(f"baseline {tmp_path / 'none.json'} does not exist"), info.value


def test_the_scene_set_compares_the_names_relations_carry_not_the_configured_ones():
    """A ``module:function`` scene (``myscenes:make``) is configured as 'make' (``meta.scenes``, the test ids) and
    loads a scene named 'plane' (the relation records): a relation added on it was told the scene set differs."""
    base = Baseline({"m.py::test_a[make]": _on("plane", "m.py::test_a[make]")})
    base.meta = {"scenes": ["make"]}
    (_, added) = compare_paired(base, [_replayed(base["m.py::test_a[make]"], [0.1] * 3),
                                       _on("plane", "m.py::test_b[make]")],
                                collected={"m.py::test_a[make]", "m.py::test_b[make]"}, scenes={"plane"})
    assert (added.outcome, added.message) == ("new", ("not in the baseline: nothing to compare with (save a new "
                                              "baseline to include it)"))
    (missing,) = compare_paired(base, [], collected=set(), scenes={"plane"})
    assert missing.message.startswith("in the baseline but no test of this id was collected"), missing.message


def test_a_folder_is_not_a_baseline(tmp_path):
    with pytest.raises(BaselineError) as info:
        load_baseline(tmp_path)
    assert str(info.value) == (f"baseline {tmp_path} is a folder; expected a baseline file (the JSON file that "
                               f"--n2r-save-baseline PATH writes, e.g. {tmp_path / 'n2r-baseline.json'})")


def test_a_rootdir_reached_through_a_link_is_recorded_as_the_same_place(tmp_path):
    """pytest keeps a rootdir reached through a symlink as given, while the baseline's folder was resolved: the
    baseline recorded '../../../link/proj' for its own project, and a clone elsewhere got a false 'rootdir differs'."""
    from pytest_n2r.report.baseline import portable_places

    (tmp_path / "real" / "proj" / "tests").mkdir(parents=True)
    (tmp_path / "link").symlink_to(tmp_path / "real")
    proj = tmp_path / "link" / "proj"
    places = portable_places({"rootdir": str(proj), "config_file": str(proj / "pyproject.toml")},
                             proj / "tests" / "gate.json")
    assert places == {"rootdir": "..", "config_file": "pyproject.toml"}, places


def test_a_margin_of_0_passes_an_unchanged_relation():
    """``mean:0`` allows no increase at all: an unchanged SUT (every change 0, so a bound of exactly 0) is within it.
    Compared with ``>=``, the bound 0 "exceeded" the margin 0 and an unchanged run was called worse."""
    base = _relation("a::t", [0.1, 0.3, 0.0, 0.25] * 5)
    (c,) = compare_paired({"a::t": base}, [_replayed(base, [e.deviation for e in base.examples])],
                          margin=parse_margin("mean:0"))
    assert (c.outcome, c.bound, c.fails) == ("ok", 0.0, False), (
        f"an unchanged relation under margin 0 was judged {c.verdict} (bound {c.bound}): {c.message}")


def test_a_test_run_again_is_judged_on_its_last_record():
    """Of several records of one test id (a test rerun in the session), the comparison takes the last: judging the
    first gated the relation on a stale record (worse here, though its rerun replayed the baseline unchanged)."""
    base = _relation("a::t", [0.1, 0.3, 0.0, 0.25] * 5)
    stale = _replayed(base, [e.deviation + 0.5 for e in base.examples])
    rerun = _replayed(base, [e.deviation for e in base.examples])
    (c,) = compare_paired({"a::t": base}, [stale, rerun], margin=0.02)
    assert (c.outcome, c.mean_change, c.fails) == ("ok", 0.0, False), (
        f"judged on the stale first record: {c.verdict}, mean change {c.mean_change}")
    (c,) = compare_paired({"a::t": base}, [rerun, stale], margin=0.02)
    assert c.outcome == "worse" and c.mean_change == pytest.approx(0.5), (
        f"the last record (worse) was not the one judged: {c.verdict}, mean change {c.mean_change}")
