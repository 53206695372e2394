"""Turn what a SUT returned into clean numpy arrays, or raise :class:`SUTOutputError` naming the output.

``which`` is ``"source"`` or ``"follow-up"``: messages read "follow-up output contains 3 NaN values".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import MetricUndefined, SUTOutputError

__all__ = ["as_numeric", "as_vector", "as_keypoints"]


def _to_numpy(value: Any) -> Any:
    """Tensors (torch: any device, any float dtype incl. bfloat16) to float64 numpy; others unchanged."""
    if hasattr(value, "detach") and hasattr(value, "cpu") and hasattr(value, "double"):
        return value.detach().cpu().double().numpy()
    return value


def as_numeric(value: Any, which: str, expected: str) -> np.ndarray:
    """``value`` as a finite float64 array; ``expected`` describes the accepted form for messages."""
    if value is None:
        raise SUTOutputError(f"{which} output is None; expected {expected}")
    value = _to_numpy(value)
    try:
        arr = np.asarray(value)
        kind = arr.dtype.kind
        if kind != "c":
            arr = arr.astype(np.float64, copy=False)
    except (TypeError, ValueError) as exc:
        raise SUTOutputError(
            f"{which} output of type {type(value).__name__} is not numeric; expected {expected}"
        ) from exc
    if kind == "c":
        raise SUTOutputError(f"{which} output is complex; expected {expected}")
    if not np.all(np.isfinite(arr)):
        n_nan = int(np.count_nonzero(np.isnan(arr)))
        n_inf = int(np.count_nonzero(np.isinf(arr)))
        parts = [f"{n_nan} NaN" if n_nan else "", f"{n_inf} infinite" if n_inf else ""]
        raise SUTOutputError(f"{which} output contains {' and '.join(p for p in parts if p)} values")
    return arr


def as_vector(value: Any, which: str) -> np.ndarray:
    """A classifier output as a 1-D float64 vector; a batch of one (``(1, C)``, Keras style) is accepted.

    An empty or all-NaN vector is the SUT saying nothing: :class:`MetricUndefined` (the pair tests
    nothing), not an error; a vector with *some* NaN values is a :class:`SUTOutputError`.
    """
    expected = "a 1-D vector of class scores of shape (C,) or a batch of one (1, C)"
    raw = _to_numpy(value)
    if (isinstance(raw, (list, tuple)) and len(raw) == 0) or (isinstance(raw, np.ndarray) and raw.size == 0):
        raise MetricUndefined(f"the {which} output is empty (nothing to compare)")
    if isinstance(raw, np.ndarray) and raw.dtype.kind == "f" and np.isnan(raw).all():
        raise MetricUndefined(f"the {which} output is all NaN (nothing to compare)")
    arr = as_numeric(raw, which, expected)
    if arr.ndim == 2 and arr.shape[0] == 1:
        arr = arr[0]
    if arr.ndim != 1:
        raise SUTOutputError(f"{which} output has shape {arr.shape}; expected {expected}")
    if arr.size == 0:
        raise SUTOutputError(f"{which} output is empty; expected {expected}")
    return arr


def as_keypoints(value: Any, which: str) -> np.ndarray:
    """Keypoints as an ``(N, 2)`` float64 array of ``(u, v)`` pixels (OpenCV pixel centres).

    Accepts an ``(N, 2)`` array, an ``(N, K >= 2)`` array whose extra columns (score, size, ...) are
    dropped, an empty sequence, or a sequence of ``cv2.KeyPoint`` (their ``pt``).
    """
    expected = "keypoints as an (N, 2) array of (u, v) pixels, an (N, K>=2) array, or a list of cv2.KeyPoint"
    if isinstance(value, Sequence) and not isinstance(value, (str, bytes)):
        if len(value) == 0:
            return np.zeros((0, 2))
        if all(hasattr(k, "pt") for k in value):
            value = [k.pt for k in value]
    arr = as_numeric(value, which, expected)
    if arr.size == 0 and arr.ndim <= 2:
        return np.zeros((0, 2))
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise SUTOutputError(f"{which} output has shape {arr.shape}; expected {expected}")
    return np.ascontiguousarray(arr[:, :2])
