"""Exposure measured from the photos alone (pytest_n2r.data.exposure): the gains a phone's automatic exposure and
white balance put on each photo, recovered where neighbouring photos see the same points."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pytest_n2r.data import ingest
from pytest_n2r.data.exposure import ExposureSpread, log_gains_from_ratios, measure_exposure
from pytest_n2r.data.triangulate import matched_pairs, triangulate_views
from pytest_n2r.demo.phone_capture import PhoneSettings, write_phone_capture
from pytest_n2r.errors import InvalidArgument
from pytest_n2r.fit.appearance import APPEARANCE_JUMP, needs_appearance
from pytest_n2r.geometry import project

#: Phone captures of the demo wall (every photo of its trajectory) at the size the measurement was checked at:
#: at 240 px too few matches link the trajectory's second half to its first.
SIZE = 480


@pytest.fixture(scope="module")
def phone(tmp_path_factory):
    """``{settings name: (training views, true log gains (photos, RGB) of the stored values)}``."""
    out = {}
    for name, settings in {"varied": PhoneSettings(size=SIZE),
                           "steady": PhoneSettings(size=SIZE, exposure_stops=0.0, white_balance=0.0)}.items():
        folder = tmp_path_factory.mktemp(name)
        photos = {p.path.name: p for p in write_phone_capture("wall", folder, settings)}
        views = ingest(folder, downscale=1.0).train_views
        # the phone multiplies linear light; the stored (sRGB, gamma 2.2) values scale by the gain ** (1 / 2.2)
        truth = np.array([np.log(photos[v.name].gain * np.array(photos[v.name].white_balance)) / 2.2
                          for v in views])
        out[name] = (views, truth - truth.mean(axis=0))
    return out


def test_gains_of_a_phone_capture_are_recovered(phone):
    views, truth = phone["varied"]
    measured = measure_exposure(views)
    assert measured.measured.all(), f"photos not measured: {np.array(measured.names)[~measured.measured]}"
    error = np.sqrt(np.mean((measured.log_gains - truth) ** 2))
    # measured at 480 px (benchmarks/exposure.py, 6 December 18:26 UTC, portrait photos upright): 0.0070 RMS
    # against a drawn spread of 0.080 (0.0143 with the portrait photos on their side, 15:20 UTC)
    assert error < 0.03, f"gains off the truth by {error:.4f} (RMS of natural-log gains)"
    true_spread = float(np.sqrt(np.mean(np.var(truth, axis=0))))
    assert abs(measured.spread - true_spread) < 0.25 * true_spread, (measured.spread, true_spread)
    assert needs_appearance(measured), f"±0.5 stops: neighbours differ by {measured.jump:.4f}, no correction"


def test_a_steady_camera_measures_below_the_threshold(phone):
    views, _ = phone["steady"]
    measured = measure_exposure(views)
    # blur and JPEG alone, the wall at 480 px: jump 0.0053, spread 0.0065, residual 0.0028 (benchmarks/exposure.py,
    # 6 December 18:26 UTC; the object 0.0034, 0.0111, 0.0040)
    assert measured.jump < APPEARANCE_JUMP / 3, f"a steady camera jumps {measured.jump:.4f}"
    assert measured.spread < 0.03 and not needs_appearance(measured), measured.summary()
    assert measured.residual < 0.01, f"pairs left {measured.residual:.4f} unexplained"


def test_a_drift_along_the_path_is_spread_not_jump(phone):
    """A colour that drifts slowly from the first photo to the last (a video's exposure following the light)
    is a large spread, but neighbours barely differ: the field's view-dependent colour follows it."""
    views, _ = phone["steady"]
    drift = np.linspace(-0.15, 0.15, len(views))  # natural log: 35 % from the first photo to the last
    drifted = [dataclasses.replace(v, image=np.clip(v.image * np.exp(d), 0, 255).round().astype(np.uint8))
               for v, d in zip(views, drift)]
    measured = measure_exposure(drifted)
    assert measured.measured.all()
    np.testing.assert_allclose(measured.log_gains.mean(axis=1), drift, atol=0.03,
                               err_msg="the drift is not what the gains measure")
    # measured (6 December 18:28 UTC): spread 0.087 (the drift's own 0.087), jump 0.013 against the steady
    # camera's 0.005
    assert measured.spread > 0.07 and not needs_appearance(measured), measured.summary()


def test_nothing_to_compare_is_no_measurement(phone):
    views, _ = phone["varied"]
    alone = measure_exposure(views[:1])
    assert alone.spread is None and alone.jump is None and alone.residual is None
    assert alone.pairs == [] and not alone.measured.any()
    assert not needs_appearance(alone), "a capture that could not be measured is no evidence of varied exposure"
    assert alone.summary()["spread"] is None and alone.summary()["jump"] is None


def test_photos_without_images_are_named(phone):
    views, _ = phone["varied"]
    bare = [dataclasses.replace(v, image=None) for v in views[:2]] + list(views[2:4])
    with pytest.raises(InvalidArgument, match=f"not loaded: {views[0].name}, {views[1].name}"):
        measure_exposure(bare)
    for bad, message in (({"patch_px": 0}, "patch_px=0"), ({"neighbours": 0}, "neighbours=0"),
                         ({"max_side": 10}, "max_side=10: expected an integer >= 64")):
        with pytest.raises(InvalidArgument, match=message):
            measure_exposure(views[:2], **bad)


def test_matches_meet_at_their_points_and_make_the_triangulated_points(phone):
    views, _ = phone["steady"]
    images, cameras, c2ws = [v.image for v in views], [v.camera for v in views], [v.c2w for v in views]
    pairs = matched_pairs(images, cameras, c2ws)
    assert len(pairs) > len(views), f"only {len(pairs)} pairs matched among {len(views)} photos"
    for m in pairs:
        for k, uv in ((m.i, m.ui), (m.j, m.uj)):
            projected, z = project(m.points, cameras[k], c2ws[k])
            error = np.linalg.norm(projected - uv, axis=1)
            assert (z > 0).all() and (error < 2.0).all(), f"pair {m.i, m.j}: reprojection up to {error.max():.2f} px"
    np.testing.assert_array_equal(np.concatenate([m.points for m in pairs]),
                                  triangulate_views(images, cameras, c2ws))


@given(gains=st.lists(st.floats(-1, 1), min_size=3, max_size=12), extra=st.integers(0, 20), seed=st.integers(0, 99))
def test_exact_ratios_give_the_gains_back(gains, extra, seed):
    """Ratios of a chain plus random extra pairs, exact: the gains come back with their mean removed; a photo
    without a pair is NaN."""
    g = np.array(gains)
    n = len(g)
    rng = np.random.default_rng(seed)
    pairs = [(k, k + 1) for k in range(n - 2)]  # photo n-1 is left out
    pairs += [tuple(sorted(rng.choice(n - 1, 2, replace=False).tolist())) for _ in range(extra)]
    ratios = np.array([[g[i] - g[j]] for i, j in pairs])
    out = log_gains_from_ratios(n, pairs, ratios)[:, 0]
    assert np.isnan(out[-1]), "a photo with no pair was given a gain"
    np.testing.assert_allclose(out[:-1], g[:-1] - g[:-1].mean(), atol=1e-9)


def test_ratios_need_a_row_per_pair():
    with pytest.raises(InvalidArgument, match=r"ratios has shape \(3,\); expected \(3, channels\)"):
        log_gains_from_ratios(4, [(0, 1), (1, 2), (2, 3)], np.zeros(3))


def test_pairs_name_two_different_photos():
    with pytest.raises(InvalidArgument, match=r"pairs holds \(2, 2\); expected two different photos in 0\.\.3"):
        log_gains_from_ratios(4, [(0, 1), (2, 2)], np.zeros((2, 1)))
    with pytest.raises(InvalidArgument, match=r"pairs holds \(0, 4\)"):
        log_gains_from_ratios(4, [(0, 4)], np.zeros((1, 1)))


def test_a_chain_of_pairs_leaves_nothing_to_compare():
    """Gains fitted exactly to a chain of pairs are no evidence that one gain per photo explains the capture."""
    chain = ExposureSpread(["a", "b", "c"], log_gains_from_ratios(3, [(0, 1), (1, 2)], np.array([[0.1] * 3,
                                                                                                 [0.2] * 3])),
                           [(0, 1), (1, 2)], np.array([[0.1] * 3, [0.2] * 3]), 40)
    assert chain.residual is None and chain.summary()["residual"] is None


def test_the_largest_linked_group_is_measured():
    out = log_gains_from_ratios(5, [(0, 1), (2, 3), (3, 4)], np.array([[0.2], [0.1], [0.1]]))[:, 0]
    assert np.isnan(out[:2]).all(), "photos 0 and 1 are linked to none of the larger group"
    np.testing.assert_allclose(out[2:], [0.1, 0.0, -0.1], atol=1e-12)


def test_summary_is_json_ready():
    gains = np.array([[0.1] * 3, [-0.1] * 3, [np.nan] * 3])
    pairs = [(0, 1), (0, 1)]  # one pair seen twice: one more ratio than the gains need
    spread = ExposureSpread(["a", "b", "c"], gains, pairs, np.array([[0.2, 0.2, 0.23], [0.2, 0.2, 0.17]]), 40)
    summary = spread.summary()
    assert summary["spread"] == 0.1 and summary["photos"] == 2 and summary["of"] == 3 and summary["pairs"] == 2
    assert summary["jump"] == 0.2005 and summary["residual"] == 0.0173
    assert list(summary["gains"]) == ["a", "b"] and summary["gains"]["a"] == [1.1052] * 3
    json.dumps(summary)
