"""Image quality between a test image and a reference image: PSNR, SSIM and (when available) LPIPS.

Used to judge how real rendered views are (a render against the held-out photo at the same pose) and
how far a mutation moves an image. Images are H×W×3 (or H×W) arrays of the same shape: ``uint8`` with
values 0..255, or floats with values in [0, 1] (or pass ``data_range``).

LPIPS needs the ``lpips`` package, ``torchvision`` and the ImageNet backbone weights in the torch hub
cache (``torch.hub.get_dir()/checkpoints``). They are never downloaded: when any is missing,
:func:`lpips` warns once (:class:`LPIPSUnavailable`) and returns ``None``.
"""

from __future__ import annotations

import importlib.util
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import check_array, check_positive
from ..errors import InvalidArgument, InvalidType, SUTOutputError
from ._outputs import as_image
from .base import Metric, MetricResult

__all__ = ["psnr", "ssim", "lpips", "lpips_unavailable_reason", "LPIPSUnavailable", "SSIM", "ssim_metric"]

#: torchvision checkpoint file of each LPIPS backbone (what ``lpips.LPIPS(net=...)`` would download).
LPIPS_BACKBONES = {
    "alex": "alexnet-owt-7be5be79.pth",
    "vgg": "vgg16-397923af.pth",
    "squeeze": "squeezenet1_1-b8a52dc0.pth",
}


#: What an image-returning SUT's output must be, for messages.
_IMAGE = "an H×W×3 or H×W image (uint8, or floats in [0, 1] unless data_range is given)"


class LPIPSUnavailable(UserWarning):
    """LPIPS cannot run here (package, torchvision or backbone weights missing); it is skipped."""


def _pair(image_true: Any, image_test: Any, data_range: float | None,
          names: tuple[str, str] = ("image_true", "image_test")) -> tuple[np.ndarray, np.ndarray, float]:
    """Both images as float64 arrays and their data range; errors name the images by ``names``."""
    a = check_array(names[0], image_true, "H W" if np.ndim(image_true) == 2 else "H W 3")
    b = check_array(names[1], image_test, "H W" if np.ndim(image_test) == 2 else "H W 3")
    if a.shape != b.shape:
        raise InvalidArgument(f"{names[0]} has shape {a.shape} but {names[1]} has {b.shape}; expected equal shapes")
    if a.dtype != b.dtype:
        raise InvalidType(f"{names[0]} is {a.dtype} but {names[1]} is {b.dtype}; expected the same dtype")
    if data_range is not None:
        data_range = check_positive("data_range", data_range)
    elif a.dtype == np.uint8:
        data_range = 255.0
    elif a.dtype.kind == "f":
        for name, image in zip(names, (a, b), strict=True):
            lo, hi = float(image.min()), float(image.max())
            if lo < 0.0 or hi > 1.0:
                raise InvalidArgument(f"{name} is a float image with values in [{lo:.4g}, {hi:.4g}], not [0, 1]; "
                                      "pass data_range= (the span of values an image can take, e.g. 255)")
        data_range = 1.0
    else:
        raise InvalidType(f"images of dtype {a.dtype} need data_range=; expected uint8 (0..255) or float (0..1)")
    return a.astype(np.float64), b.astype(np.float64), float(data_range)


def psnr(image_true: np.ndarray, image_test: np.ndarray, *, data_range: float | None = None) -> float:
    """Peak signal-to-noise ratio in dB: ``10 log10(data_range² / MSE)``; ``inf`` for identical images.

    >>> a = np.zeros((4, 4, 3), np.uint8)
    >>> round(psnr(a, a + 1), 2)
    48.13
    """
    a, b, data_range = _pair(image_true, image_test, data_range)
    mse = float(np.mean((a - b) ** 2))
    return math.inf if mse == 0.0 else 10.0 * math.log10(data_range**2 / mse)


def ssim(image_true: np.ndarray, image_test: np.ndarray, *, data_range: float | None = None) -> float:
    """Structural similarity (Wang et al. 2004) in [-1, 1], 1 for identical images.

    scikit-image with the paper's settings: an 11×11 Gaussian window (σ = 1.5), population covariance,
    averaged over channels. Images must be at least 11 pixels on each side.
    """
    return _ssim(*_pair(image_true, image_test, data_range))


def _check_ssim_size(a: np.ndarray) -> None:
    """SSIM's 11×11 window needs images of at least 11 pixels a side."""
    if min(a.shape[:2]) < 11:
        raise InvalidArgument(f"images of {a.shape[1]}x{a.shape[0]} pixels are too small for SSIM; expected >= 11x11")


def _ssim(a: np.ndarray, b: np.ndarray, data_range: float) -> float:
    """SSIM of two float64 images of one shape (as :func:`_pair` returns them)."""
    from skimage.metrics import structural_similarity

    _check_ssim_size(a)
    return float(structural_similarity(
        a, b, data_range=data_range, channel_axis=-1 if a.ndim == 3 else None,
        gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
    ))


def lpips_unavailable_reason(net: str = "alex") -> str | None:
    """Why LPIPS with backbone ``net`` cannot run here, or ``None`` when it can (nothing is downloaded)."""
    if net not in LPIPS_BACKBONES:
        raise InvalidArgument(f"net={net!r}; expected one of {tuple(LPIPS_BACKBONES)}")
    for package in ("lpips", "torchvision"):
        if importlib.util.find_spec(package) is None:
            return f"the {package!r} package is not installed"
    import torch

    weights = Path(torch.hub.get_dir()) / "checkpoints" / LPIPS_BACKBONES[net]
    if not weights.is_file():
        return f"the {net} backbone weights are not at {weights} (they would have to be downloaded)"
    return None


_warned: set[str] = set()
_models: dict[str, Any] = {}


def lpips(image_true: np.ndarray, image_test: np.ndarray, *, net: str = "alex") -> float | None:
    """Learned perceptual distance (Zhang et al. 2018), 0 for identical images, lower is closer.

    Returns ``None``, warning once per reason (:class:`LPIPSUnavailable`), when LPIPS cannot run here.
    Images are uint8 (or floats in [0, 1]) H×W×3 RGB.
    """
    reason = lpips_unavailable_reason(net)
    if reason is not None:
        if reason not in _warned:
            _warned.add(reason)
            warnings.warn(f"LPIPS skipped: {reason}", LPIPSUnavailable, stacklevel=2)
        return None
    a, b, data_range = _pair(image_true, image_test, None)
    if a.ndim != 3:
        raise InvalidType(f"LPIPS needs H×W×3 RGB images, got shape {a.shape}")
    import torch

    if net not in _models:
        import lpips as lpips_package

        _models[net] = lpips_package.LPIPS(net=net, verbose=False).eval()

    def tensor(x: np.ndarray) -> torch.Tensor:  # H×W×3 in [0, data_range] → 1×3×H×W in [-1, 1]
        return torch.from_numpy(x / data_range * 2.0 - 1.0).permute(2, 0, 1)[None].float()

    with torch.no_grad():
        return float(_models[net](tensor(a), tensor(b)).reshape(-1)[0])


class SSIM(Metric):
    """SSIM between the SUT's two output *images* (for SUTs that return images: denoisers, enhancers).

    Range [-1, 1], ideal 1, deviation ``1 - score``; see :func:`ssim`. The outputs may be numpy arrays or
    tensors (any device, ``requires_grad`` or not; bfloat16 is read as float32). ``data_range`` is the span of
    values an output image can take: 255 for uint8 and 1 for floats unless given (float images in 0..255 need
    ``data_range=255``). Any output it cannot use is a :class:`~pytest_n2r.errors.SUTOutputError` naming it.
    The same constant image twice (a blank output) is *undefined*: SSIM would score it 1 with no structure
    compared, so a SUT that returns black for every image would pass every relation. Two different constant
    images are scored (their luminance differs: black against white is a change).
    """

    name = "ssim"
    ideal = 1.0

    def __init__(self, data_range: float | None = None) -> None:
        self.data_range = None if data_range is None else check_positive("data_range", data_range)

    def compute(self, out_source: Any, out_follow: Any, source: Any = None, follow: Any = None) -> MetricResult:
        a, b = (as_image(out, which, _IMAGE) for which, out in (("source", out_source), ("follow-up", out_follow)))
        try:
            pair = _pair(a, b, self.data_range, ("source output", "follow-up output"))
            if _constant(a) and np.array_equal(a, b):  # no structure compared: a blank output would score 1
                _check_ssim_size(a)
                return MetricResult.undefined(self.name, "both outputs are the same constant image (every pixel "
                                              f"{_first_pixel(a)}): nothing to compare")
            score = _ssim(*pair)
        except (InvalidArgument, InvalidType) as exc:  # about the outputs (data_range was checked when built)
            raise SUTOutputError(str(exc)) from None
        return self.result(score)

    def __repr__(self) -> str:
        return "ssim_metric()" if self.data_range is None else f"ssim_metric(data_range={self.data_range!r})"


def _constant(image: np.ndarray) -> bool:
    """Whether every pixel of an H×W or H×W×C image is the same."""
    pixels = image.reshape(image.shape[0] * image.shape[1], -1)
    return bool(np.all(pixels == pixels[:1]))


def _first_pixel(image: np.ndarray) -> str:
    """The first pixel's value(s), as text."""
    return np.array2string(image.reshape(image.shape[0] * image.shape[1], -1)[0], precision=4)


def ssim_metric(data_range: float | None = None) -> SSIM:
    """The :class:`SSIM` metric for relations whose SUT returns images; ``data_range``: the span of an image's
    values (default: 255 for uint8, 1 for floats in [0, 1])."""
    return SSIM(data_range)
