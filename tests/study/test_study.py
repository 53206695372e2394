"""`n2r study` on an exact demo scene at tiny sizes: every table filled, counts consistent, errors clear."""

from __future__ import annotations

import csv
import dataclasses
import json
import math

import numpy as np
import pytest

from pytest_n2r.cli.main import main
from pytest_n2r.demo import ground_truth
from pytest_n2r.errors import InvalidArgument, InvalidType
from pytest_n2r.strategies import PRESET_FAMILIES
from pytest_n2r.study import StudyConfig, resolve_sut, run_study, write_study
from pytest_n2r.study.correlation import rank_correlations
from pytest_n2r.study.fidelity import FidelityReport, measure_fidelity
from pytest_n2r.study.run import StudyResult
from pytest_n2r.study.sampling import sample_mutation, sample_transform
from tests.plugin.fakefield import BlurredPlane

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
            if not valid:  # nothing compared: no count, not zero inconsistencies
                assert math.isnan(row[f"inc@{eps:g}"]), row
                continue
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


class _EmptyOnTheLeft:
    """The exact wall scene with the left ``share`` of a render's columns empty (opacity 0): in every render (like an
    object in the open, every view, the source too, shows some empty space), or ``moved_only`` in renders at poses
    other than its captured views' (every follow-up of a moved pose emptier than its source, while the detector's
    points on the rest still compare)."""

    def __init__(self, share: float, moved_only: bool = False) -> None:
        self._scene = ground_truth("wall")
        self.share, self.moved_only = share, moved_only

    def __getattr__(self, name: str):
        return getattr(self._scene, name)

    def render(self, c2w, camera, outputs=("rgb",)):
        view = self._scene.render(c2w, camera, outputs)
        if view.opacity is None or self.moved_only and any(np.allclose(c2w, v.c2w) for v in self._scene.views):
            return view
        opacity = view.opacity.copy()
        opacity[:, : int(self.share * opacity.shape[1])] = 0.0
        return dataclasses.replace(view, opacity=opacity)


def test_follow_ups_are_judged_against_their_source_view():
    # 160 px: at 64 ORB (31-px borders) finds no keypoint, and an example with nothing to compare is not valid
    config = StudyConfig(examples=2, max_views=1, size=160, fps_frames=1, fps_sizes=((64, 36),),
                         families=("tau1",))
    result = run_study([_EmptyOnTheLeft(0.3)], [resolve_sut("orb", None)], config)
    valid = [r["valid"] for r in result.examples]
    assert valid and all(valid), (
        f"τ1 follow-ups of a view that is itself 30 % empty were rejected ({valid}): the validity check must "
        "compare the follow-up's empty share with the source view's, not with a full view")


def batch_classifier(rgb):
    """A classifier returning a batch of one score vector, shape (1, 10), as Keras models do."""
    scores = np.bincount((rgb[..., 0].ravel() // 26).astype(int), minlength=10)[:10].astype(np.float64)
    return (scores / scores.sum())[None, :]


def test_a_batch_of_one_output_needs_its_kind_said():
    """(1, K) is one keypoint or a batch of one score vector: once taken for a detector (one keypoint, scored
    near-perfect), it is now an error naming the SUT, the shape and the option, unless the kind is given."""
    probe = np.random.default_rng(0).integers(0, 256, (16, 16, 3), dtype=np.uint8)
    spec = "tests.study.test_study:batch_classifier"
    with pytest.raises(InvalidType, match=rf"--sut {spec}: .*shape \(1, 10\).*--sut-kind {spec}=classifier"):
        resolve_sut(spec, probe)
    sut = resolve_sut(spec, probe, kind="classifier")
    assert sut.kind == "classifier" and set(sut.metrics()) == {"cosine", "l2", "class_invariance"}
    with pytest.raises(InvalidType, match=r"--sut numpy:ravel is a detector \(--sut-kind\), but its output .*shape "
                                          r"\(768,\)"):
        resolve_sut("numpy:ravel", probe, kind="detector")
    with pytest.raises(InvalidArgument, match="the built-in orb is a detector"):
        resolve_sut("orb", probe, kind="classifier")


def test_cli_study_takes_the_kind_of_an_ambiguous_sut(tmp_path, capsys):
    spec = "tests.study.test_study:batch_classifier"
    args = ["study", "demo:wall", "--sut", spec, "--examples", "1", "--views", "1", "--size", "64",
            "--fps-size", "64x36", "--fps-frames", "1"]
    assert main([*args, "-o", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert f"--sut {spec}: its output on the probe image has shape (1, 10)" in err and "--sut-kind" in err, err
    assert main([*args, "-o", str(tmp_path / "b"), "--sut-kind", "nope=classifier"]) == 2
    assert "--sut-kind nope=classifier: 'nope' is not one of the --sut given" in capsys.readouterr().err
    assert main([*args, "-o", str(tmp_path / "c"), "--sut-kind", f"{spec}=classifier"]) == 0
    with open(tmp_path / "c" / "examples.csv") as fh:
        metrics = {row["metric"] for row in csv.DictReader(fh)}
    assert metrics == {"cosine", "l2", "class_invariance"}, f"scored as {metrics}"


def _rows(valid: bool, n: int = 2) -> list[dict]:
    return [{"scene": "s", "view": f"v{i}", "family": "tau1", "drawn": "yaw=1", "sut": "orb", "metric": "repeatability",
             "score": 0.5 if valid else math.nan, "deviation": 0.5 if valid else math.nan, "valid": valid}
            for i in range(n)]


def test_a_family_with_no_valid_example_counts_nothing_not_zero(tmp_path):
    result = StudyResult(examples=_rows(False), eps=(0.1, 0.2))
    (row,) = result.inconsistencies
    assert row["valid"] == 0 and all(math.isnan(row[f"inc@{e:g}"]) for e in (0.1, 0.2)), (
        f"a family that compared nothing was counted as {row}: zero inconsistencies would read as a pass")
    write_study(result, tmp_path)
    assert "| s | orb | repeatability | tau1 | n2r | 2 | 0 | — | — |" in (tmp_path / "study.md").read_text()


def test_the_means_say_how_many_samples_they_cover(tmp_path):
    shift = [{"scene": "s", "view": f"v{i}", "sut": "orb", "metric": "repeatability", "score": 0.8,
              "deviation": 0.2, "valid": True} for i in range(2)]
    shift.append({**shift[0], "view": "v2", "score": math.nan, "deviation": math.nan, "valid": False})
    write_study(StudyResult(domain_shift=shift), tmp_path)
    text = (tmp_path / "study.md").read_text()
    assert "| scene | sut | metric | score | deviation | n | n_valid |" in text, text
    assert "| s | orb | repeatability | 0.8 | 0.2 | 3 | 2 |" in text, "n counts the samples, n_valid those averaged"


def test_plots_of_an_earlier_run_are_not_left_in_the_folder(study, tmp_path):
    pytest.importorskip("matplotlib")
    first = {p.name for p in write_study(study, tmp_path)}
    assert {"rq1_realness.png", "rq3_fps.png"} <= first, first
    write_study(StudyResult(), tmp_path)  # draws no plot: nothing to draw
    left = sorted(p.name for p in tmp_path.glob("*.png"))
    assert not left, f"plots of the earlier run were left beside this run's tables: {left}"


def test_the_fidelity_report_is_strict_json():
    """`n2r info --json --shift` once printed NaN (not JSON) for scores with no defined sample."""
    report = FidelityReport("s", "64", "photo", "", ({"view": "v0", "psnr": math.inf, "ssim": 1.0},), {})
    data = json.loads(json.dumps(report.to_dict(), allow_nan=False))
    assert data["images"][0]["psnr"] is None and data["psnr"] is None, data
    assert data["detectors"]["orb"] == {"repeatability": None, "ip_spread": None}, data["detectors"]


class _RightHalfEmpty(BlurredPlane):
    """A field that renders the photo exactly on the left half and nothing (opacity 0, black) on the right."""

    @property
    def content_hash(self) -> str:  # not the whole plane's: what is kept by scene content must not be shared
        return "right half empty " + super().content_hash

    def _render(self, c2w, camera, outputs):
        out = super()._render(c2w, camera, outputs)
        right = slice(camera.width // 2, None)
        for key in ("rgb", "opacity"):
            if key in out:
                out[key][:, right] = 0
        return out


def test_the_reality_to_field_shift_counts_the_photos_points_where_the_field_rendered_nothing():
    """The shift mapped points through the rendered depth, which left out of both sides the photo's points where the
    render was empty: a field that rendered half of every photo black scored a spread of 1.0. The paper pairs the
    points of one pose by the identity; the study's RQ1 and the fidelity report do now."""
    scene = _RightHalfEmpty(blur=0.0, name="half", width=160, height=120)
    report = measure_fidelity(scene, size=None)
    spreads = {d: report.score(d, "ip_spread") for d in ("orb", "sift", "akaze")}
    assert all(score < 0.8 for score in spreads.values()), f"the empty half went uncounted: {spreads}"
    result = run_study([scene], [resolve_sut("orb", None)], dataclasses.replace(TINY, size=160))
    rows = {row["metric"]: row["score"] for row in result.domain_shift}
    assert rows["ip_spread"] < 0.8, f"RQ1's shift left the empty half out: {rows}"


@pytest.mark.parametrize("name", ["mobilenet_v2", "efficientnet_lite0"])
def test_the_example_classifiers_are_study_suts_by_name(name, monkeypatch):
    """docs/study.md runs the paper's classifier half with ``--sut perception.classifiers:<name>``."""
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "example_project"))
    sut = resolve_sut(f"perception.classifiers:{name}", np.full((120, 160, 3), 90, np.uint8))
    scores = sut.fn(np.full((120, 160, 3), 90, np.uint8))
    assert sut.kind == "classifier" and scores.shape == (1000,), (sut.kind, scores.shape)
    assert abs(float(scores.sum()) - 1.0) < 1e-4, f"{name}: probabilities sum to {scores.sum()}"


def _shift_rows(quality: list[float], scores: list[float], **row) -> tuple[list[dict], list[dict]]:
    """RQ1's τ0 realness rows (PSNR ``quality``, SSIM and LPIPS from it) and ORB's shift rows with ``scores``."""
    realness = [{"scene": "s", "view": f"v{i}", "source": "tau0", "psnr": q, "ssim": q / 40, "lpips": 1 - q / 40}
                for i, q in enumerate(quality)]
    shift = [{"scene": "s", "view": f"v{i}", "sut": "orb", "metric": "repeatability", "score": score,
              "deviation": 1 - score, "valid": True, **row} for i, score in enumerate(scores)]
    return realness, shift


def test_image_quality_and_sut_scores_are_rank_correlated_as_the_paper_tests_them(tmp_path):
    """The paper tests Spearman rank correlations between PSNR, SSIM, LPIPS and each SUT metric under the
    reality-to-field shift (38 of its 48 combinations significant at p < 0.05); the study did not compute them."""
    realness, shift = _shift_rows([20.0, 24.0, 22.0, 27.0, 25.0, 29.0], [0.3, 0.5, 0.4, 0.8, 0.6, 0.9])
    result = StudyResult(realness=realness, domain_shift=shift)
    rows = {r["image_quality"]: r for r in result.correlations}
    assert set(rows) == {"psnr", "ssim", "lpips"}, rows
    assert rows["psnr"]["rho"] == pytest.approx(1.0) and rows["ssim"]["rho"] == pytest.approx(1.0), rows
    assert rows["lpips"]["rho"] == pytest.approx(-1.0), "lower LPIPS is the more faithful render: a negative rho"
    assert all(r["n"] == 6 and r["p"] < 0.05 and r["significant"] for r in rows.values()), rows
    written = {p.name for p in write_study(result, tmp_path)}
    assert "correlations.csv" in written, written
    with open(tmp_path / "correlations.csv") as fh:
        assert [r["image_quality"] for r in csv.DictReader(fh)] == ["psnr", "ssim", "lpips"]
    assert "3 of 3 combinations with a rank correlation are significant at p < 0.05" in (
        tmp_path / "study.md").read_text()


def test_a_correlation_of_nothing_to_rank_is_undefined_not_zero():
    """Too few views, a constant column, invalid samples, exact renders (the reference itself: no field, no
    shift) and a missing LPIPS have no rank correlation: NaN and not significant, never a measured independence."""
    cases = {  # case: (rows, the pairs each combination should count)
        "two views": (_shift_rows([20.0, 25.0], [0.3, 0.9]), 2),
        "constant scores": (_shift_rows([20.0, 25.0, 22.0, 27.0], [0.5] * 4), 4),
        "invalid samples": (_shift_rows([20.0, 25.0, 22.0, 27.0], [0.3, 0.9, 0.5, 0.7], valid=False), 0),
        "exact renders": (_shift_rows([math.inf] * 4, [1.0, 0.9, 0.8, 0.7]), None),
    }
    for case, ((realness, shift), pairs) in cases.items():
        rows = rank_correlations(realness, shift)
        if pairs is None:  # no view of a field: no combination to report
            assert rows == [], (case, rows)
            continue
        assert [r["n"] for r in rows] == [pairs] * 3, (case, rows)
        assert all(math.isnan(r["rho"]) and math.isnan(r["p"]) and not r["significant"] for r in rows), (case, rows)
    realness, shift = _shift_rows([20.0, 25.0, 22.0, 27.0], [0.3, 0.9, 0.5, 0.7])
    for row in realness:
        row["lpips"] = None  # the lpips package is not installed
    lpips_row = next(r for r in rank_correlations(realness, shift) if r["image_quality"] == "lpips")
    assert lpips_row["n"] == 0 and math.isnan(lpips_row["rho"]), lpips_row


def test_a_study_of_exact_scenes_says_there_is_nothing_to_correlate(study, tmp_path):
    assert study.correlations == [], "an exact scene's τ0 is its own reference: no shift to correlate"
    write_study(study, tmp_path)
    assert "nothing to correlate" in (tmp_path / "study.md").read_text()


def test_a_few_views_get_the_exact_p_value_not_the_t_approximation(tmp_path):
    """Three views ranked alike are one ordering in three of six (both directions): p = 1/3, not significant. The
    t approximation SciPy's spearmanr uses gives 0 there, and 0.037 for five views at rho 0.9 (exactly 1/12)."""
    from scipy.stats import permutation_test, spearmanr

    realness, shift = _shift_rows([20.0, 22.0, 25.0], [0.3, 0.5, 0.9])
    rows = rank_correlations(realness, shift)
    assert all(r["rho"] == pytest.approx(1.0) and r["p"] == pytest.approx(abs(r["rho"]) / 3) and not r["significant"]
               for r in rows if r["image_quality"] != "lpips"), rows
    write_study(StudyResult(realness=realness, domain_shift=shift), tmp_path)
    line = next(t for t in (tmp_path / "study.md").read_text().splitlines() if "combinations" in t)
    assert "0 of 3 combinations" in line and "3 of them on too few views to reach p < 0.05 at all" in line, (
        f"three views read as no dependence, not as too few to tell: {line}")
    x, y = [20.0, 20.0, 22.0, 23.0, 25.0, 21.0, 24.0], [0.3, 0.2, 0.2, 0.6, 0.9, 0.5, 0.4]  # ties in both
    psnr = next(r for r in rank_correlations(*_shift_rows(x, y)) if r["image_quality"] == "psnr")
    exact = permutation_test((x,), lambda a: abs(spearmanr(a, y).statistic), permutation_type="pairings",
                             n_resamples=10**6, alternative="greater")  # every pairing: P(|rho| >= |observed|)
    assert abs(psnr["rho"]) == pytest.approx(exact.statistic) and psnr["p"] == pytest.approx(exact.pvalue), (
        psnr, exact.statistic, exact.pvalue)


def test_eight_views_still_get_the_exact_p_value():
    """Exact up to EXACT_UP_TO (8) pairs: eight views ranked alike are 2 of the 8! pairings, p = 2/40 320, where
    the t approximation gives 0."""
    realness, shift = _shift_rows([20.0 + i for i in range(8)], [0.1 * i for i in range(8)])
    psnr_row = next(r for r in rank_correlations(realness, shift) if r["image_quality"] == "psnr")
    assert psnr_row["n"] == 8 and psnr_row["rho"] == pytest.approx(1.0), psnr_row
    assert psnr_row["p"] == pytest.approx(2 / math.factorial(8)), f"8 views: p {psnr_row['p']}, exactly 2/8!"


def _plane_study(blur: float, monkeypatch, **config) -> StudyResult:
    """A study of a plane field blurred ``blur`` pixels whose held-out views store the sharp photo (no LPIPS)."""
    import pytest_n2r.study.run as study_run

    monkeypatch.setattr(study_run, "lpips", lambda *_a, **_k: None)
    scene = BlurredPlane(blur=blur, name="plane", width=64, height=48)
    config = StudyConfig(**{"examples": 1, "max_views": 4, "size": 64, "fps_frames": 1, "fps_sizes": ((32, 24),),
                            "families": ("m1",), **config})
    return run_study([scene], [resolve_sut("orb", None)], config)


def test_the_study_measures_the_heldout_views_not_the_fitted_ones(monkeypatch):
    """The reality-to-field shift of a fit is measured where it was not fitted (views 1 and 3 of the plane)."""
    result = _plane_study(1.0, monkeypatch)
    for name, rows in (("realness", result.realness), ("domain_shift", result.domain_shift),
                       ("examples", result.examples)):
        views = sorted({r["view"] for r in rows})
        assert views == ["view1", "view3"], f"{name} measured the views {views}, expected the held-out view1, view3"


def test_rq1_mutates_the_photo_not_the_render(monkeypatch):
    """m1-m3 are the baseline of a mutated real photo against the photo: the field's blur changes τ0's row only."""
    sharp, blurred = ({(r["view"], r["source"]): (r["psnr"], r["ssim"])
                       for r in _plane_study(blur, monkeypatch).realness} for blur in (1.0, 3.0))
    assert set(sharp) == set(blurred) and {source for _, source in sharp} == {"tau0", "m1", "m2", "m3"}, sharp
    for key in sharp:
        if key[1] == "tau0":
            assert blurred[key][0] < sharp[key][0], f"{key}: a blurrier field did not score lower: {blurred[key]}"
        else:
            assert blurred[key] == sharp[key], f"{key}: the mutated photo's scores moved with the field's blur"


@pytest.mark.parametrize(("width", "height", "sizes"), [(32, 24, [(32, 24), (64, 48)]), (24, 32, [(24, 32), (48, 64)])],
                         ids=["landscape", "portrait"])
def test_frames_per_second_are_of_one_frame(monkeypatch, width, height, sizes):
    """RQ3 times ``fps_frames`` renders after a warm-up: a render of 0.25 s is 4 frames a second; a portrait scene
    is timed at the sizes turned upright."""
    import types

    import pytest_n2r.study.run as study_run
    from tests.plugin.fakescene import PlaneScene

    clock = [0.0]

    class Timed(PlaneScene):
        def render(self, c2w, camera, outputs=("rgb",)):
            clock[0] += 0.25
            return super().render(c2w, camera, outputs)

    monkeypatch.setattr(study_run, "time", types.SimpleNamespace(perf_counter=lambda: clock[0]))
    result = StudyResult()
    config = StudyConfig(fps_frames=4, fps_sizes=((32, 24), (64, 48)))
    study_run._rq3(result, Timed(name="timed", width=width, height=height), config, lambda _message: None)
    assert [(r["width"], r["height"]) for r in result.fps] == sizes, f"a {width}x{height} scene timed at {result.fps}"
    for row in result.fps:
        assert row["seconds_per_frame"] == pytest.approx(0.25) and row["fps"] == pytest.approx(4.0), (
            f"four 0.25 s renders reported as {row}")


def test_the_mutation_draws_are_the_families_the_study_states():
    """pytest_n2r/study/sampling.py: m1 ±13 to ±77 grey levels of either sign, m2 one noise patch of 20-50 % of the
    sides anywhere, m3 six black patches of 3-8 % each."""
    rng = np.random.default_rng(0)
    levels = [sample_mutation("m1", rng).levels for _ in range(200)]
    assert all(13 <= abs(level) <= 77 for level in levels), f"m1 drew {sorted(set(levels))}"
    assert min(levels) <= -70 and max(levels) >= 70 and min(map(abs, levels)) <= 20, (
        f"200 m1 draws span {min(levels)}..{max(levels)}: not both signs of the whole range")
    noise = [sample_mutation("m2", rng) for _ in range(50)]
    assert all(0.2 <= m.size <= 0.5 and 0 <= m.x <= 1 and 0 <= m.y <= 1 for m in noise), noise
    black = [sample_mutation("m3", rng) for _ in range(50)]
    assert all(m.count == 6 and 0.03 <= m.size <= 0.08 for m in black), black


def test_detectors_are_scored_with_the_papers_parameters():
    """Repeatability within 2 pixels and spread of 8-pixel discs; between two poses through the rendered depth,
    at one pose (the reality-to-field shift) through the identity."""
    sut = resolve_sut("orb", None)
    across = {name: repr(metric) for name, metric in sut.metrics().items()}
    same = {name: repr(metric) for name, metric in sut.same_pose_metrics().items()}
    assert across == {"repeatability": "repeatability(px=2.0, matching='maximum', mapping='depth')",
                      "ip_spread": "interest_point_spread(radius=8.0, mapping='depth')"}, across
    assert same == {"repeatability": "repeatability(px=2.0, matching='maximum', mapping='homography')",
                    "ip_spread": "interest_point_spread(radius=8.0, mapping='homography')"}, same


def test_the_fidelity_report_averages_the_defined_samples_and_prints_each_in_its_column():
    from pytest_n2r.relation.floor import FieldFloor, ShiftSample

    def floor(metric: str, samples: tuple, nearby: tuple) -> FieldFloor:
        return FieldFloor("s", "orb", metric, "64", "photo", samples=samples, nearby=nearby, nearby_degrees=5.0)

    undefined = ShiftSample("v1", math.nan, math.nan, False, "no keypoint")
    floors = {("orb", "repeatability"): floor("repeatability", (ShiftSample("v0", 0.6, 0.4, True), undefined),
                                              (ShiftSample("v0", 0.9, 0.1, True), undefined)),
              ("orb", "ip_spread"): floor("ip_spread", (ShiftSample("v0", 0.3, 0.7, True), undefined),
                                          (ShiftSample("v0", 0.2, 0.8, True), undefined))}
    images = ({"view": "v0", "psnr": 20.0, "ssim": 0.5}, {"view": "v1", "psnr": 30.0, "ssim": 0.7})
    report = FidelityReport("s", "64", "photo", "", images, floors)
    got = (report.score("orb", "repeatability"), report.score("orb", "ip_spread"), report.nearby_score("orb"))
    assert got == (0.6, 0.3, 0.9), f"repeatability, spread and nearby repeatability {got}, expected (0.6, 0.3, 0.9)"
    line = next(t.split() for t in report.format().splitlines() if t.strip().startswith("orb"))
    assert line == ["orb", "0.600", "0.300", "0.900"], f"the orb row reads {line}: not repeatability, spread, nearby"


def test_the_fidelity_report_measures_every_detector_on_the_views_it_scores():
    """``max_views`` bounds the detectors' samples as it bounds the PSNR rows: the table says "mean of n views"."""
    report = measure_fidelity(BlurredPlane(blur=1.0, name="two", width=160, height=120), size=None, max_views=1)
    views = [row["view"] for row in report.images]
    assert len(views) == 1, views
    for key, floor in report.floors.items():
        measured = [s.view for s in floor.samples]
        assert measured == views, f"{key} measured the views {measured}, the report scores {views}"


def test_the_realness_summary_has_a_row_per_scene_and_source(tmp_path):
    realness = [{"scene": scene, "view": "v0", "source": "tau0", "psnr": psnr, "ssim": 0.5, "lpips": None}
                for scene, psnr in (("a", 20.0), ("b", 30.0))]
    write_study(StudyResult(realness=realness), tmp_path)
    text = (tmp_path / "study.md").read_text()
    for row in ("| a | tau0 | 20 | 0.5 | — | 1 | 1 |", "| b | tau0 | 30 | 0.5 | — | 1 | 1 |"):
        assert row in text, f"the RQ1 table has no row {row}: {text}"


def test_follow_ups_emptier_than_their_source_are_not_counted_as_inconsistencies():
    config = StudyConfig(examples=2, max_views=1, size=160, fps_frames=1, fps_sizes=((64, 36),), families=("tau1",))
    result = run_study([_EmptyOnTheLeft(0.4, moved_only=True)], [resolve_sut("orb", None)], config)
    assert result.examples and not any(r["valid"] for r in result.examples), (
        f"follow-ups 40 % emptier than their source were judged valid: {[r['valid'] for r in result.examples]}")


def test_an_imported_sut_without_a_probe_image_is_refused():
    """A probe image tells an imported SUT's kind (a built-in's is known: None will do there)."""
    with pytest.raises(InvalidArgument, match=r"--sut 'numpy:ravel' is imported: probe=None; expected an RGB image"):
        resolve_sut("numpy:ravel", None)


def test_a_scene_whose_render_leaves_out_rgb_is_named_not_given_to_the_sut(monkeypatch):
    """A scene of one's own whose render returns no rgb had None handed to the SUT (OpenCV's error, or the SUT's)."""
    scene = BlurredPlane(photos=False)
    original = scene._render
    monkeypatch.setattr(scene, "_render", lambda c2w, cam, outputs: {
        k: v for k, v in original(c2w, cam, outputs).items() if k != "rgb"})
    with pytest.raises(InvalidArgument, match=r"rendered nothing as 'rgb'; its _render must return every output"):
        run_study([scene], [resolve_sut("orb", None)], TINY)
