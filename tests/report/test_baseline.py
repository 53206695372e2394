"""Baselines round-trip, compare by rules on deviations, and fail clearly on bad files."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pytest_n2r.errors import InvalidArgument, N2RError
from pytest_n2r.report import (
    CompareRule, ExampleRecord, RelationRecord, compare_runs, load_baseline, parse_compare_rules, save_baseline,
)
from pytest_n2r.report.baseline import format_comparison_table
from pytest_n2r.report.records import deviation_stats


def _relation(nodeid: str, deviations: list[float], eps: float = 0.2, metric: str = "repeatability(px=2.0)"):
    examples = [
        ExampleRecord("wall", f"view{i}", {"yaw": float(i)}, 1.0 - d, d, d <= eps) for i, d in enumerate(deviations)
    ]
    return RelationRecord(nodeid, metric, eps, examples)


def test_round_trip_keeps_every_example(tmp_path):
    rel = _relation("t.py::test_orb", [0.0, 0.1, 0.3])
    path = save_baseline(tmp_path / "base.json", [rel], meta={"scene": "wall"})
    loaded = load_baseline(path)
    assert list(loaded) == ["t.py::test_orb"]
    got = loaded["t.py::test_orb"]
    assert [e.key() for e in got.examples] == [e.key() for e in rel.examples]
    assert [e.deviation for e in got.examples] == [0.0, 0.1, 0.3]


def test_baseline_file_is_stable_and_sorted(tmp_path):
    rels = [_relation("b::t", [0.1]), _relation("a::t", [0.2])]
    first = save_baseline(tmp_path / "1.json", rels).read_text()
    second = save_baseline(tmp_path / "2.json", list(reversed(rels))).read_text()
    assert first == second, "the baseline must not depend on the order relations ran in"
    assert list(json.loads(first)["relations"]) == ["a::t", "b::t"]


def test_no_temporary_file_is_left_behind(tmp_path):
    save_baseline(tmp_path / "base.json", [_relation("a::t", [0.1])])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["base.json"]


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (None, "does not exist; create it with --n2r-save-baseline"),
        ("{not json", "not readable JSON"),
        ('{"format": "other"}', "is not a pytest-n2r baseline"),
        ('{"format": "pytest-n2r-baseline", "version": 99}', "format version 99"),
        ('{"format": "pytest-n2r-baseline", "version": 1, "relations": {"a": {"eps": 1}}}', "relation 'a' is malformed"),
    ],
)
def test_bad_baseline_files_say_what_is_wrong(tmp_path, content, expected):
    path = tmp_path / "base.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(N2RError, match=expected):
        load_baseline(path)


def test_compare_flags_worse_relation_and_passes_equal_one():
    base = {r.nodeid: r for r in [_relation("a::t", [0.1, 0.1]), _relation("b::t", [0.1, 0.1])]}
    current = [_relation("a::t", [0.1, 0.1]), _relation("b::t", [0.3, 0.3])]
    result = {c.nodeid: c for c in compare_runs(base, current, parse_compare_rules("mean:0.05"))}
    assert result["a::t"].status == "ok"
    assert result["b::t"].status == "worse"
    assert "mean:0.05" in result["b::t"].failed_rules[0]
    table = format_comparison_table(list(result.values()))
    assert "0.100→0.300" in table and "worse" in table


def test_compare_reports_new_and_stale_relations():
    base = {"a::t": _relation("a::t", [0.1], eps=0.2)}
    current = [_relation("a::t", [0.1], eps=0.5), _relation("c::t", [0.1])]
    status = {c.nodeid: c.status for c in compare_runs(base, current, [CompareRule("mean", 0.0)])}
    assert status == {"a::t": "stale", "c::t": "new"}


def test_percent_rules():
    rule = CompareRule("p90", 10.0, percent=True)
    assert rule.fails(0.2, 0.23) and not rule.fails(0.2, 0.21)
    assert rule.fails(0.0, 0.01), "any growth from a zero baseline is infinitely many percent"


@pytest.mark.parametrize("spec", ["mean", "mean:", "avg:0.1", "mean:-1", "p90:abc"])
def test_bad_rule_specs_name_the_option(spec):
    with pytest.raises(InvalidArgument, match="--n2r-compare-fail"):
        parse_compare_rules(spec)


@given(st.lists(st.floats(0, 10, allow_nan=False), min_size=1, max_size=50), st.floats(0, 10))
def test_stats_are_ordered_and_bounded(devs, eps):
    s = deviation_stats(devs, eps)
    assert min(devs) <= s["p10"] <= s["median"] <= s["p90"] <= s["max"] == max(devs)
    assert min(devs) - 1e-9 <= s["mean"] <= max(devs) + 1e-9
    assert 0.0 <= s["rate"] <= 1.0


def test_stats_of_nothing_are_nan():
    assert all(math.isnan(v) for v in deviation_stats([], 0.1).values())
