"""`n2r study` on an exact demo scene at tiny sizes: every table filled, counts consistent, errors clear."""

from __future__ import annotations

import csv
import dataclasses
import math

import numpy as np
import pytest

from pytest_n2r.cli.main import main
from pytest_n2r.demo import ground_truth
from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.strategies import PRESET_FAMILIES
from pytest_n2r.study import StudyConfig, resolve_sut, run_study, write_study
from pytest_n2r.study.sampling import sample_mutation, sample_transform

TINY = StudyConfig(examples=1, max_views=1, size=64, fps_frames=1, fps_sizes=((64, 36),))


@pytest.fixture(scope="module")
def study():
    scene = ground_truth("wall")
    return run_study([scene], [resolve_sut("orb", None)], TINY)


def test_every_research_question_has_rows(study):
    sources = {r["source"] for r in study.realness}
    assert sources == {"tau0", "m1", "m2", "m3"}, sources
    assert all(r["psnr"] == math.inf for r in study.realness if r["source"] == "tau0"), \
        "an exact scene's render at the captured pose is the reference itself"
    assert {r["metric"] for r in study.domain_shift} == {"repeatability", "ip_spread"}
    assert len(study.examples) == 9 * 2, "one draw per family (6 τ + 3 m) for each of the two ORB metrics"
    assert [(r["width"], r["height"]) for r in study.fps] == [(64, 36)] and study.fps[0]["fps"] > 0


def test_inconsistency_counts_agree_with_examples(study):
    for row in study.inconsistencies:
        rows = [e for e in study.examples
                if (e["sut"], e["metric"], e["family"]) == (row["sut"], row["metric"], row["family"])]
        valid = [e for e in rows if e["valid"]]
        assert row["drawn"] == len(rows) and row["valid"] == len(valid)
        for eps in TINY.eps:
            assert row[f"inc@{eps:g}"] == sum(e["deviation"] > eps for e in valid)
            assert row[f"inc@{eps:g}"] <= row["valid"]


def test_outputs_are_written(study, tmp_path):
    paths = write_study(study, tmp_path)
    names = {p.name for p in paths}
    assert {"realness.csv", "inconsistencies.csv", "fps.csv", "study.md"} <= names
    with open(tmp_path / "inconsistencies.csv") as fh:
        assert len(list(csv.DictReader(fh))) == len(study.inconsistencies)
    text = (tmp_path / "study.md").read_text()
    assert "## RQ1" in text and "## RQ2" in text and "## RQ3" in text


def test_draws_are_reproducible_and_within_bounds():
    for family, pose_changes in PRESET_FAMILIES.items():
        a = sample_transform(family, np.random.default_rng(3))
        assert a == sample_transform(family, np.random.default_rng(3))
        assert abs(a.roll) <= pose_changes.bounds.get("roll", (0, 0))[1] + 1e-12
    assert sample_mutation("m2", np.random.default_rng(1)) == sample_mutation("m2", np.random.default_rng(1))
    with pytest.raises(KeyError, match="unknown mutation family"):
        sample_mutation("m9", np.random.default_rng(0))


def test_imported_sut_kind_is_detected():
    probe = np.zeros((8, 8, 3), np.uint8)
    sut = resolve_sut("numpy:ravel", probe)
    assert sut.kind == "classifier" and set(sut.metrics()) == {"cosine", "l2", "class_invariance"}


@pytest.mark.parametrize(
    ("spec", "error", "match"),
    [("surf", InvalidArgument, "not a built-in SUT"), ("nope_module:f", InvalidArgument, "cannot import"),
     ("math:pi", InvalidType, "not a callable")],
)
def test_bad_sut_specs(spec, error, match):
    with pytest.raises(error, match=match):
        resolve_sut(spec, np.zeros((8, 8, 3), np.uint8))


def test_bad_config():
    with pytest.raises(InvalidArgument, match="examples=0"):
        StudyConfig(examples=0)
    with pytest.raises(InvalidArgument, match="families"):
        StudyConfig(families=("tau9",))


def test_cli_end_to_end(tmp_path, capsys):
    code = main(["study", "demo:object", "--sut", "orb", "-o", str(tmp_path), "--examples", "1", "--views", "1",
                 "--size", "64", "--fps-size", "64x36", "--fps-frames", "1"])
    assert code == 0
    assert (tmp_path / "study.md").is_file() and (tmp_path / "examples.csv").is_file()
    assert "wrote" in capsys.readouterr().out


def test_cli_rejects_bad_eps(capsys):
    with pytest.raises(SystemExit):
        main(["study", "demo:wall", "--sut", "orb", "-o", "x", "--eps", "a,b"])
    assert "--eps 'a,b'" in capsys.readouterr().err


def test_missing_lpips_is_explained_once_in_the_notes(monkeypatch):
    import pytest_n2r.study.run as study_run

    monkeypatch.setattr(study_run, "lpips", lambda *_a, **_k: None)
    monkeypatch.setattr(study_run, "lpips_unavailable_reason", lambda: "the 'lpips' package is not installed")
    config = StudyConfig(examples=1, max_views=2, size=48, fps_frames=1, fps_sizes=((48, 27),),
                         families=("m1",))
    result = run_study([ground_truth("wall")], [resolve_sut("orb", None)], config)
    assert result.realness and all(r["lpips"] is None for r in result.realness)
    notes = [n for n in result.notes if n.startswith("LPIPS skipped")]
    assert notes == ["LPIPS skipped (column empty): the 'lpips' package is not installed"], \
        f"expected one note saying why the LPIPS column is empty, got notes {result.notes}"


class _HalfEmptyScene:
    """The exact wall scene with the left 30 % of every render's columns empty (opacity 0): like an object
    in the open, every view — the source too — shows some empty space."""

    def __init__(self) -> None:
        self._scene = ground_truth("wall")

    def __getattr__(self, name: str):
        return getattr(self._scene, name)

    def render(self, c2w, camera, outputs=("rgb",)):
        view = self._scene.render(c2w, camera, outputs)
        if view.opacity is None:
            return view
        opacity = view.opacity.copy()
        opacity[:, : int(0.3 * opacity.shape[1])] = 0.0
        return dataclasses.replace(view, opacity=opacity)


def test_follow_ups_are_judged_against_their_source_view():
    # 160 px: at 64 ORB (31-px borders) finds no keypoint, and an example with nothing to compare is not valid
    config = StudyConfig(examples=2, max_views=1, size=160, fps_frames=1, fps_sizes=((64, 36),),
                         families=("tau1",))
    result = run_study([_HalfEmptyScene()], [resolve_sut("orb", None)], config)
    valid = [r["valid"] for r in result.examples]
    assert valid and all(valid), (
        f"τ1 follow-ups of a view that is itself 30 % empty were rejected ({valid}): the validity check must "
        "compare the follow-up's empty share with the source view's, not with a full view")
