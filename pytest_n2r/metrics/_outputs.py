"""Turn what a SUT returned into clean numpy arrays, or raise :class:`SUTOutputError` naming the output.

``which`` is ``"source"`` or ``"follow-up"``: messages read "follow-up output contains 3 NaN values".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .._validation import is_tensor, tensor_values
from ..errors import MetricUndefined, SUTOutputError

__all__ = ["as_numeric", "as_vector", "as_keypoints", "as_image", "float_eps"]

_FLOAT64_EPS = float(np.finfo(np.float64).eps)


def _to_numpy(value: Any) -> Any:
    """Tensors (torch: any device and dtype) as numpy arrays of their values
    (:func:`~pytest_n2r._validation.tensor_values`: bfloat16 as float32); others unchanged."""
    if is_tensor(value):
        return tensor_values(value)
    return value


def _as_float_array(value: Any, which: str, expected: str) -> np.ndarray:
    """``value`` as a float64 array (NaN and Inf kept); ``None``, complex or non-numeric is a SUTOutputError."""
    if value is None:
        raise SUTOutputError(f"{which} output is None; expected {expected}")
    value = _to_numpy(value)
    try:
        arr = np.asarray(value)
        kind = arr.dtype.kind
        if kind != "c":
            arr = arr.astype(np.float64, copy=False)
    except OverflowError as exc:  # a Python int beyond float64's range (10**400)
        raise SUTOutputError(f"{which} output holds a number too large for a float64 ({exc}); expected {expected}"
                             ) from exc
    except (TypeError, ValueError) as exc:
        raise SUTOutputError(
            f"{which} output of type {type(value).__name__} is not numeric; expected {expected}"
        ) from exc
    if kind == "c":
        raise SUTOutputError(f"{which} output is complex; expected {expected}")
    return arr


def as_numeric(value: Any, which: str, expected: str) -> np.ndarray:
    """``value`` as a finite float64 array; ``expected`` describes the accepted form for messages."""
    arr = _as_float_array(value, which, expected)
    if not np.all(np.isfinite(arr)):
        n_nan = int(np.count_nonzero(np.isnan(arr)))
        n_inf = int(np.count_nonzero(np.isinf(arr)))
        parts = [f"{n_nan} NaN" if n_nan else "", f"{n_inf} infinite" if n_inf else ""]
        raise SUTOutputError(f"{which} output contains {' and '.join(p for p in parts if p)} values")
    return arr


def as_vector(value: Any, which: str) -> np.ndarray:
    """A classifier output as a 1-D float64 vector; a batch of one (``(1, C)``, Keras style) is accepted.

    An empty or all-NaN output (array, tensor or list alike) is the SUT saying nothing: :class:`MetricUndefined`
    naming the output (the vector metrics score it against the other output's answer), not an error; a vector with
    *some* NaN values is a :class:`SUTOutputError`.
    """
    expected = "a 1-D vector of class scores of shape (C,) or a batch of one (1, C)"
    arr = _as_float_array(value, which, expected)
    if arr.size == 0:
        raise MetricUndefined(f"the {which} output is empty")
    if np.isnan(arr).all():
        raise MetricUndefined(f"the {which} output is all NaN")
    arr = as_numeric(arr, which, expected)
    if arr.ndim == 2 and arr.shape[0] == 1:
        arr = arr[0]
    if arr.ndim != 1:
        raise SUTOutputError(f"{which} output has shape {arr.shape}; expected {expected}")
    return arr


def float_eps(value: Any) -> float:
    """Machine epsilon of the floating dtype a SUT output came in (bfloat16 2**-7, float16 2**-10, float32
    2**-23); that of float64 for Python floats, integers and anything else."""
    if is_tensor(value):
        import torch

        return float(torch.finfo(value.dtype).eps) if value.dtype.is_floating_point else _FLOAT64_EPS
    dtype = value.dtype if isinstance(value, np.ndarray) else np.asarray(value).dtype
    return float(np.finfo(dtype).eps) if dtype.kind == "f" else _FLOAT64_EPS


def as_image(value: Any, which: str, expected: str) -> np.ndarray:
    """An image output as a numpy array of its own dtype (uint8 stays uint8): tensors are detached and moved
    to the CPU, bfloat16 (which numpy lacks) becomes float32. ``None``, non-numeric, complex, NaN or Inf
    outputs are a :class:`SUTOutputError` naming the output, as in :func:`as_numeric`."""
    if is_tensor(value):
        value = tensor_values(value)  # once: checked and returned from the host copy
    as_numeric(value, which, expected)
    return np.asarray(value)


def as_keypoints(value: Any, which: str) -> np.ndarray:
    """Keypoints as an ``(N, 2)`` float64 array of ``(u, v)`` pixels (OpenCV pixel centres).

    Accepts an ``(N, 2)`` array, an ``(N, K >= 2)`` array whose extra columns (score, size, ...) are
    dropped, an empty sequence, or a sequence of ``cv2.KeyPoint`` (their ``pt``). A ``(3, K >= 4)`` array whose
    last row lies in [0, 1] while the others reach past 1 is refused: that is how SuperPoint's reference code returns
    ``K`` keypoints (rows ``x``, ``y``, confidence), and as rows its third keypoint would sit within a pixel of the
    image's corner with a size and a score of at most 1, which no detector reports; any other ``(3, K)`` array is
    three rows. A ``(2, K)`` array is two keypoints (docs/metrics.md, "Keypoint metrics").
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
    if arr.shape[0] == 3 and arr.shape[1] >= 4 and _transposed(arr):
        raise SUTOutputError(
            f"{which} output has shape {arr.shape} and its last row lies in [0, 1]: the transposed (x, y, "
            f"confidence) rows of {arr.shape[1]} keypoints, as SuperPoint returns them? Return one row per keypoint, "
            "(N, 2) (u, v) or (N, 3) (u, v, score): pts.T for (3, N)")
    return np.ascontiguousarray(arr[:, :2])


def _transposed(arr: np.ndarray) -> bool:
    """Whether the ``(3, K)`` keypoint array ``arr`` reads as SuperPoint's transposed rows (``x``, ``y``,
    confidence in [0, 1]) rather than three keypoints (:func:`as_keypoints`)."""
    coordinates = np.abs(arr[:2][np.isfinite(arr[:2])])
    return bool(np.all((arr[2] >= 0) & (arr[2] <= 1)) and coordinates.size and coordinates.max() > 1)
