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
    a[4:8, 4:8] = 0.5
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


containers = {
    "numpy": lambda x: x,
    "tensor": torch.from_numpy,
    "tensor requiring grad": lambda x: torch.tensor(x, dtype=torch.float32, requires_grad=True),
    "bfloat16 tensor": lambda x: torch.tensor(x, dtype=torch.bfloat16),
}


@settings(max_examples=30, deadline=None)
@given(image=images, seed=st.integers(0, 2**16), container=st.sampled_from(sorted(containers)))
def test_ssim_metric_reads_arrays_and_tensors_alike(image, seed, container):
    """A tensor requiring grad raised torch's bare RuntimeError, bfloat16 an InvalidType: the metric now reads
    them as the other metrics do (detached, on the CPU, bfloat16 as float32)."""
    other = np.random.default_rng(seed).integers(0, 256, size=image.shape, dtype=np.uint8)
    a, b = image / 255.0, other / 255.0  # in [0, 1], exact in bfloat16 only to 8 bits: compare with what it holds
    wrap = containers[container]
    expected = iq.ssim(*(np.asarray(torch.as_tensor(wrap(x)).detach().float().numpy(), np.float64) for x in (a, b)))
    result = iq.ssim_metric()(wrap(a), wrap(b))
    assert result.score == pytest.approx(expected, abs=1e-6), f"{container}: {result.score} vs {expected}"


def test_ssim_metric_takes_a_data_range_for_float_images_in_0_to_255():
    rng = np.random.default_rng(0)
    a, b = rng.random((32, 32, 3)) * 255, rng.random((32, 32, 3)) * 255
    with pytest.raises(SUTOutputError, match=r"source output is a float image with values in \[.*\], not \[0, 1\]; "
                                             r"pass data_range="):
        iq.ssim_metric()(a, b)
    assert iq.ssim_metric(data_range=255)(a, b).score == pytest.approx(iq.ssim(a / 255, b / 255), abs=1e-9), (
        "data_range=255 on 0..255 images should equal SSIM of the images scaled to 0..1")
    assert repr(iq.ssim_metric(data_range=255)) == "ssim_metric(data_range=255.0)", "repr drops data_range"
    assert repr(iq.ssim_metric()) == "ssim_metric()", "repr of the default changed"
    with pytest.raises(InvalidArgument, match="data_range"):
        iq.ssim_metric(data_range=0)


@pytest.mark.parametrize(
    ("a", "b", "match"),
    [
        (np.zeros((16, 16, 3)), np.zeros((16, 17, 3)),
         r"source output has shape \(16, 16, 3\) but follow-up output has \(16, 17, 3\)"),
        (np.zeros((16, 16, 3), np.uint8), np.zeros((16, 16, 3)),
         "source output is uint8 but follow-up output is float64"),
        (np.zeros((16, 16, 3)), np.zeros((3, 16, 16)),
         r"follow-up output must have shape \(H W 3\), got \(3, 16, 16\)"),
        (np.zeros((16, 16, 3)), np.full((16, 16, 3), 2.0),
         r"follow-up output is a float image with values in \[2, 2\]"),
        (np.zeros((5, 16, 3)), np.zeros((5, 16, 3)), "too small for SSIM"),
        (np.zeros((16, 16), np.int64), np.zeros((16, 16), np.int64), "images of dtype int64 need data_range="),
        (None, np.zeros((16, 16)), "source output is None; expected an H×W×3 or H×W image"),
    ],
)
def test_ssim_metric_errors_name_the_output(a, b, match):
    """The metric's errors named image_true / image_test, arguments its caller never passed."""
    with pytest.raises(SUTOutputError, match=match):
        iq.ssim_metric()(a, b)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")
def test_ssim_metric_reads_cuda_tensors_requiring_grad():
    a = torch.rand(32, 32, 3, device="cuda", requires_grad=True)
    assert iq.ssim_metric()(a, a * 1).score == pytest.approx(1.0), "a CUDA tensor requiring grad scored wrong"


@pytest.mark.parametrize("value", [0, 128, 255])
def test_two_constant_output_images_are_undefined_never_ideal(value):
    """A SUT that returns one blank image for every input scored SSIM 1 on every pair and passed every relation:
    two constant images compare no structure, so nothing to compare (never a perfect score)."""
    blank = np.full((16, 16, 3), value, np.uint8)
    result = iq.ssim_metric()(blank, blank.copy())
    assert not result.valid and math.isnan(result.deviation), result
    assert result.details["reason"].startswith("both outputs are the same constant image"), result.details
    flipped = iq.ssim_metric()(blank, np.full((16, 16, 3), 255 if value < 128 else 0, np.uint8))
    assert flipped.valid and flipped.deviation > 0.5, f"black against white is a change, not nothing: {flipped}"
    structured = blank.copy()
    structured[4:8, 4:8] = 255 - value
    assert iq.ssim_metric()(blank, structured).valid, "one constant output against a structured one is scored"
    assert iq.ssim(blank, blank) == pytest.approx(1.0), "the ssim function itself still compares two images"


def _skimage_ssim(a: np.ndarray, b: np.ndarray, **settings_) -> float:
    from skimage.metrics import structural_similarity

    return float(structural_similarity(a.astype(np.float64), b.astype(np.float64), data_range=255,
                                       channel_axis=-1, **settings_))


#: The settings :func:`iq.ssim` documents: the paper's 11×11 Gaussian window (σ = 1.5) and population covariance.
DOCUMENTED = {"gaussian_weights": True, "sigma": 1.5, "use_sample_covariance": False}


def test_ssim_uses_the_documented_gaussian_window_and_population_covariance():
    """ssim documents Wang et al.'s settings; a uniform 7×7 window or the sample covariance (skimage's defaults)
    gives other values (here 0.187 and 0.152 against 0.153), and results would not compare with the paper's."""
    rng = np.random.default_rng(42)
    smooth = np.clip(np.add.outer(np.arange(32), np.arange(40))[..., None] * [3, 2, 1], 0, 255).astype(np.uint8)
    noisy = np.clip(smooth + rng.normal(0, 25, smooth.shape), 0, 255).astype(np.uint8)
    expected = _skimage_ssim(smooth, noisy, **DOCUMENTED)
    for name, changed in (("a uniform window", {**DOCUMENTED, "gaussian_weights": False}),
                          ("the sample covariance", {**DOCUMENTED, "use_sample_covariance": True})):
        other = _skimage_ssim(smooth, noisy, **changed)
        assert abs(other - expected) > 1e-4, f"the pair cannot tell {name} from the documented settings"
    assert iq.ssim(smooth, noisy) == pytest.approx(expected, rel=1e-12, abs=1e-12), (
        f"ssim {iq.ssim(smooth, noisy)} is not skimage's {expected} with the documented settings {DOCUMENTED}")
    assert iq.ssim_metric()(smooth, noisy).score == pytest.approx(expected, rel=1e-12, abs=1e-12), (
        "the SSIM metric does not score what ssim() documents")


@settings(max_examples=20, deadline=None)
@given(image=images, seed=st.integers(0, 2**16))
def test_ssim_equals_skimage_with_the_documented_settings(image, seed):
    """Any pair scores what scikit-image gives with the documented settings: another window or covariance (skimage's
    defaults) went unnoticed, as the other tests only check ranges and orderings."""
    other = np.random.default_rng(seed).integers(0, 256, size=image.shape, dtype=np.uint8)
    expected = _skimage_ssim(image, other, **DOCUMENTED)
    assert iq.ssim(image, other) == pytest.approx(expected, rel=1e-12, abs=1e-12), (
        f"ssim {iq.ssim(image, other)} is not skimage's {expected} with the documented settings")
