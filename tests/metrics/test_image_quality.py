"""PSNR, SSIM and LPIPS: known values, ranges, and LPIPS skipping cleanly when it cannot run here."""

from __future__ import annotations

import math
import sys
import types
import warnings

import hypothesis.strategies as st
import numpy as np
import pytest
import torch
from hypothesis import given, settings

from pytest_n2r.errors import InvalidArgument, InvalidType, SUTOutputError
from pytest_n2r.metrics import image_quality as iq

images = st.tuples(st.integers(11, 40), st.integers(11, 40), st.integers(0, 2**16)).map(
    lambda hws: np.random.default_rng(hws[2]).integers(0, 256, size=(hws[0], hws[1], 3), dtype=np.uint8)
)


@settings(max_examples=30, deadline=None)
@given(image=images, seed=st.integers(0, 2**16))
def test_identical_images_score_the_ideal_and_others_stay_in_range(image, seed):
    other = np.random.default_rng(seed).integers(0, 256, size=image.shape, dtype=np.uint8)
    assert iq.psnr(image, image) == math.inf and iq.ssim(image, image) == pytest.approx(1.0)
    assert -1.0 <= iq.ssim(image, other) <= 1.0
    assert iq.psnr(image, other) == pytest.approx(iq.psnr(other, image))  # symmetric
    assert iq.ssim(image, other) == pytest.approx(iq.ssim(other, image))


def test_psnr_known_values_for_uint8_and_float_images():
    a = np.zeros((16, 16, 3), np.uint8)
    assert iq.psnr(a, a + 10) == pytest.approx(20 * math.log10(255 / 10))
    f = np.zeros((16, 16), np.float32)
    assert iq.psnr(f, f + 0.1) == pytest.approx(20.0, abs=1e-5)
    assert iq.psnr(f, f + 10, data_range=100) == pytest.approx(20.0, abs=1e-5)


def test_ssim_drops_with_noise():
    rng = np.random.default_rng(0)
    smooth = np.clip(np.add.outer(np.arange(64), np.arange(64)) * 2, 0, 255).astype(np.uint8)
    image = np.repeat(smooth[..., None], 3, axis=2)
    noisy = np.clip(image + rng.normal(0, 20, image.shape), 0, 255).astype(np.uint8)
    noisier = np.clip(image + rng.normal(0, 60, image.shape), 0, 255).astype(np.uint8)
    assert 1.0 > iq.ssim(image, noisy) > iq.ssim(image, noisier)


@pytest.mark.parametrize(
    ("a", "b", "error", "match"),
    [
        (np.zeros((16, 16, 3), np.uint8), np.zeros((16, 17, 3), np.uint8), InvalidArgument,
         r"image_true has shape \(16, 16, 3\) but image_test has \(16, 17, 3\)"),
        (np.zeros((16, 16, 3), np.uint8), np.zeros((16, 16, 3), np.float32), InvalidType, "same dtype"),
        (np.full((16, 16), 2.0), np.zeros((16, 16)), InvalidArgument, r"not \[0, 1\]; pass data_range="),
        (np.zeros((16, 16, 4), np.uint8), np.zeros((16, 16, 4), np.uint8), InvalidType, r"shape \(H W 3\)"),
        (np.zeros((5, 16, 3), np.uint8), np.zeros((5, 16, 3), np.uint8), InvalidArgument, "too small for SSIM"),
    ],
)
def test_bad_images_say_what_is_wrong(a, b, error, match):
    with pytest.raises(error, match=match):
        iq.ssim(a, b)


def test_ssim_metric_names_bad_sut_outputs():
    a = np.zeros((16, 16, 3), np.float64)
    assert iq.ssim_metric()(a, a).deviation == pytest.approx(0.0)
    b = a.copy()
    b[0, 0, 0] = np.nan
    with pytest.raises(SUTOutputError, match="follow-up output contains 1 NaN values"):
        iq.ssim_metric()(a, b)


def test_lpips_without_its_weights_warns_once_and_returns_none(monkeypatch):
    monkeypatch.setattr(iq, "_warned", set())
    monkeypatch.setattr(iq, "lpips_unavailable_reason", lambda net="alex": "the 'lpips' package is not installed")
    a = np.zeros((16, 16, 3), np.uint8)
    with pytest.warns(iq.LPIPSUnavailable, match="LPIPS skipped: the 'lpips' package is not installed"):
        assert iq.lpips(a, a) is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert iq.lpips(a, a) is None  # said once is enough


def test_unavailable_reason_never_downloads(monkeypatch, tmp_path):
    monkeypatch.setattr(torch.hub, "get_dir", lambda: str(tmp_path))
    reason = iq.lpips_unavailable_reason("vgg")
    assert reason is not None and ("not installed" in reason or "vgg16-397923af.pth" in reason)
    assert not any(tmp_path.iterdir()), "checking must not create or download anything"
    with pytest.raises(InvalidArgument, match="net='resnet'; expected one of"):
        iq.lpips_unavailable_reason("resnet")


def test_lpips_runs_the_model_when_it_is_available(monkeypatch):
    """With a stand-in ``lpips`` package, images reach the model as 1×3×H×W tensors in [-1, 1]."""
    seen = []

    class FakeLPIPS(torch.nn.Module):
        def __init__(self, net, verbose):
            super().__init__()
            seen.append(net)

        def forward(self, x, y):
            assert x.shape == (1, 3, 16, 20) and x.min() >= -1 and x.max() <= 1
            return (x - y).abs().mean().reshape(1, 1, 1, 1)

    monkeypatch.setitem(sys.modules, "lpips", types.SimpleNamespace(LPIPS=FakeLPIPS))
    monkeypatch.setattr(iq, "lpips_unavailable_reason", lambda net="alex": None)
    monkeypatch.setattr(iq, "_models", {})
    a = np.zeros((16, 20, 3), np.uint8)
    assert iq.lpips(a, a) == 0.0
    assert iq.lpips(a, np.full_like(a, 255)) == pytest.approx(2.0)
    assert seen == ["alex"], "the model is built once and reused"
