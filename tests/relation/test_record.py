"""The one record of a relation run: counts and reasons derived from its examples, the summary line, JSON."""

from __future__ import annotations

import json
import math
from dataclasses import asdict

from hypothesis import given
from hypothesis import strategies as st

from pytest_n2r.relation.record import ExampleRecord, RelationRecord, deviation_stats

CAMERA = {"width": 320, "height": 180, "fx": 250.0, "fy": 250.0, "cx": 159.5, "cy": 89.5, "distortion": []}


def _example(i: int, status: str = "accepted", deviation: float = 0.1, reason: str = "") -> ExampleRecord:
    ok = status == "accepted"
    return ExampleRecord("wall", f"view{i}", {"yaw": float(i)}, 1 - deviation if ok else math.nan,
                         deviation if ok else math.nan, ok and deviation <= 0.2, status=status, reason=reason,
                         scene_hash="abc", source_c2w=[1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0],
                         camera=dict(CAMERA))


def _run() -> RelationRecord:
    examples = [_example(0, deviation=0.1), _example(1, "rejected", reason="empty view"),
                _example(2, deviation=0.3), _example(3, "undefined", reason="no keypoint"),
                _example(4, "rejected", reason="outside the captured region"), _example(5, deviation=0.3),
                _example(6, "rejected", reason="empty view")]
    return RelationRecord("t.py::test[wall]", "repeatability(px=2.0)", 0.2, examples, outcome="failed",
                          timings={"render": 1.5, "sut": 0.25, "metric": 0.125}, scene="wall", scene_hash="abc",
                          renders=9, shrink_examples=4)


def test_counts_reasons_and_the_worst_example_come_from_the_examples():
    run = _run()
    assert (len(run.valid_examples), run.rejected, run.undefined, run.inconsistencies) == (3, 3, 1, 2)
    assert list(run.rejected_reasons.items()) == [("empty view", 2), ("outside the captured region", 1)]
    assert run.undefined_reasons == {"no keypoint": 1}
    assert run.worst is run.examples[2], "the first of equal deviations is the worst"
    assert run.worst_deviation == 0.3
    assert math.isnan(RelationRecord("a", "m", 0.1).worst_deviation), "no accepted example: no worst deviation"


def test_the_summary_line_names_counts_reasons_worst_and_time():
    assert _run().summary_line() == (
        "FAILED t.py::test[wall]: 3 examples, 3 rejected as invalid (2 empty view, 1 outside the captured "
        "region), 1 undefined (1 no keypoint), 2 inconsistent, worst deviation 0.3 (eps 0.2); time render "
        "1.50 s / SUT 0.25 s / metric 0.12 s"
    )


def test_the_record_round_trips_through_json_with_every_field():
    run = _run()
    run.replayed, run.minimal, run.floor = [_example(7)], _example(2, deviation=0.3), {"line": "field floor n/a"}
    text = json.dumps(run.to_dict())
    again = RelationRecord.from_dict(json.loads(text))
    assert json.dumps(again.to_dict()) == text, "NaN scores of rejected examples included"
    assert again.renders == 9 and again.shrink_examples == 4 and again.minimal.view == "view2"
    assert again.to_dict()["stats"]["max"] == 0.3 and again.summary_line() == run.summary_line()


def test_to_dict_is_asdict_with_every_container_copied():
    """The hand-written conversion (a quarter of ``asdict``'s time) gives ``asdict``'s dict, nothing shared."""
    run = _run()
    run.replayed, run.minimal = [_example(7)], _example(2, deviation=0.3)
    run.floor = {"line": "floor", "floor": {"mean": 0.4, "views": [1, 2]}, "pair": (0.5, "x")}
    run.examples[0].settings = {"steps": [1, 2], "tile": (16, 16), "name": None}
    expected = asdict(run)
    expected["stats"] = run.stats()
    got = run.to_dict()
    assert json.dumps(got) == json.dumps(expected) and repr(got) == repr(expected)
    assert got["examples"][0]["camera"] is not run.examples[0].camera, "the camera dict is shared"
    assert got["floor"]["floor"]["views"] is not run.floor["floor"]["views"], "a nested list is shared"
    assert run.examples[0].to_dict() == asdict(run.examples[0])


@given(st.lists(st.floats(0, 10), min_size=1, max_size=50), st.floats(0, 10))
def test_stats_are_ordered_and_bounded(devs, eps):
    s = deviation_stats(devs, eps)
    assert s["p10"] <= s["median"] <= s["p90"] <= s["max"] == max(devs)
    assert min(devs) <= s["mean"] <= max(devs) and 0 <= s["rate"] <= 1


def test_stats_of_nothing_are_nan():
    assert all(math.isnan(v) for v in deviation_stats([], 0.1).values())


def test_a_deviation_equal_to_eps_is_not_counted_as_inconsistent():
    """The inconsistency rate counts deviations above eps, as the engine fails them: counting ``d >= eps`` reported
    examples that passed (deviation exactly eps, e.g. 0 at eps=0) as inconsistent."""
    assert deviation_stats([0.25], 0.25)["rate"] == 0.0, "a deviation equal to eps counted as inconsistent"
    assert deviation_stats([0.0, 0.0, 0.5], 0.0)["rate"] == 1 / 3, "at eps=0 only the deviation above 0 counts"


def test_an_example_key_names_the_follow_ups_units():
    """Guards against ExampleRecord.key() without units: a yaw/translation in metres and the same numbers in
    reference units were paired as one example when comparing against a baseline."""
    metres, reference = _example(1), _example(1)
    metres.units = "metres"
    assert reference.units != metres.units, "the test needs other units"
    assert metres.key() != reference.key(), "records differing only in their follow-up's units have one key"
    assert _example(1).key() == reference.key(), "equal records must keep one key"


def test_every_counter_and_outcome_survives_the_round_trip():
    """pytest-xdist and the plugin's summary read each record back from its dict: a field from_dict dropped reads as
    its default (0 SUT calls, no "asked" note, no pytest outcome) in the terminal summary and the reports."""
    run = _run()
    run.asked, run.sut_calls, run.sut_shared, run.pytest_outcome = 40, 6, 3, "xfailed"
    again = RelationRecord.from_dict(json.loads(json.dumps(run.to_dict())))
    assert (again.asked, again.sut_calls, again.sut_shared, again.pytest_outcome) == (40, 6, 3, "xfailed")


def test_the_summary_lines_total_includes_the_field_floor():
    run = _run()
    run.timings.update(total=2.0, floor=0.5)
    assert run.summary_line().endswith("metric 0.12 s of 2.50 s"), run.summary_line()
