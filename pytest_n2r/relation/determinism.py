"""Telling a non-deterministic system under test from a real inconsistency.

A relation compares two outputs of the SUT; when the SUT gives different outputs for the same image, a
failure is noise and Hypothesis's replay of it fails at random (its raw ``FlakyFailure``). The relation
engine therefore calls the SUT a second time on the images of the first failing example and, when the
outputs differ, stops with :class:`NotDeterministic`, which shows both.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .._validation import is_tensor, tensor_values
from ..errors import SUTNotDeterministic

__all__ = ["NotDeterministic", "SUTNotDeterministic", "check_deterministic", "same_output", "show_output"]

_SHOWN_ITEMS = 6


class NotDeterministic(BaseException):
    """The escaping form of :class:`SUTNotDeterministic`: not an ``Exception``, so Hypothesis does not
    retry the example; the caller raises :meth:`error` once the search has stopped."""

    def error(self) -> SUTNotDeterministic:
        return SUTNotDeterministic(str(self))


def _plain(output: Any) -> Any:
    """``cv2.KeyPoint`` lists as ``(N, 2)`` arrays of their positions, tensors as arrays of their values
    (:func:`~pytest_n2r._validation.tensor_values`); anything else as it is."""
    if isinstance(output, (list, tuple)) and output and all(hasattr(k, "pt") for k in output):
        return np.array([k.pt for k in output], dtype=np.float64)
    if is_tensor(output):
        return tensor_values(output)
    return output


def same_output(a: Any, b: Any) -> bool:
    """Whether two SUT outputs are identical (arrays and tensors element for element, NaN equal to NaN; lists,
    tuples and dicts item for item)."""
    a, b = _plain(a), _plain(b)
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and bool(
            np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(same_output(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_output(a[k], b[k]) for k in a)
    try:
        return bool(a == b)
    except (ValueError, TypeError, RuntimeError):  # an ambiguous or failing == (a user's type): compare the text
        return repr(a) == repr(b)


def show_output(output: Any, other: Any = None) -> str:
    """A short, one-line picture of an output (its first values; for two arrays of one shape, where they
    differ)."""
    output, other = _plain(output), _plain(other)
    if isinstance(output, np.ndarray):
        head = np.array2string(output.reshape(-1)[:_SHOWN_ITEMS], precision=4, separator=", ")
        text = f"array {output.shape} {output.dtype}, first values {head}"
        if isinstance(other, np.ndarray) and other.shape == output.shape:
            differ = output != other
            if output.dtype.kind in "fc":
                differ &= ~(np.isnan(output) & np.isnan(other))
            text += f"; {int(differ.sum())} of {output.size} values differ"
        return text
    text = repr(output)
    return text if len(text) <= 200 else text[:197] + "..."


def check_deterministic(run_sut: Callable[[np.ndarray, str, str], Any], source_rgb: np.ndarray,
                        follow_rgb: np.ndarray, out_source: Any, out_follow: Any, where: str) -> None:
    """Before the first failure counts: the SUT (``run_sut(rgb, role, where)``) must give the same outputs
    again on the same two images (else the failure is its noise, and Hypothesis's replay would fail at
    random); raises :class:`NotDeterministic` showing both outputs."""
    for role, rgb, first in (("source", source_rgb, out_source), ("follow-up", follow_rgb, out_follow)):
        again = run_sut(rgb, role, where)
        if not same_output(first, again):
            raise NotDeterministic(
                f"the system under test is not deterministic: called twice on the same {role} image "
                f"({where}) it returned\n  first:  {show_output(first, again)}\n  second: "
                f"{show_output(again, first)}\nA relation cannot tell its noise from an inconsistency: seed "
                "its random generators (and fix its thread count) inside the SUT, or raise eps above the "
                "noise")
