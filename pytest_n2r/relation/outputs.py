"""Checks of what the system under test is given and what it returned, before a metric sees it, and the error it
raises."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import SUTError, SUTOutputError
from ..metrics.base import Metric
from ..render.view import RenderedView

__all__ = ["SUTError", "check_output", "sut_image"]


def sut_image(view: RenderedView, role: str) -> np.ndarray:
    """The image the system under test is given on the ``role`` view: its ``rgb``, or an
    :class:`~pytest_n2r.errors.InvalidArgument` naming the view when it has none (a follow-up of one's own that
    builds its view without it)."""
    return view.output("rgb", name=f"the {role} view given to the system under test")


def check_output(output: Any, role: str, where: str, metric: Metric) -> None:
    """Reject outputs no metric can use: None and non-finite numbers (with the metric's expectation).

    An array that is *entirely* NaN goes to a metric whose ``nan_means_no_output`` is set (the vector
    metrics), which reads it as "no output" (undefined)."""
    __tracebackhide__ = True
    expects = getattr(metric, "expects", None) or f"what {metric.name} compares"
    if output is None:
        raise SUTOutputError(
            f"the system under test returned None on the {role} view ({where}); expected {expects}. "
            "Did the SUT forget a return statement?"
        )
    if isinstance(output, (float, np.floating)) and not math.isfinite(output):
        raise SUTOutputError(
            f"the system under test returned {output} on the {role} view ({where}); expected {expects}")
    if isinstance(output, np.ndarray) and output.dtype.kind in "fc" and not np.isfinite(output).all() \
            and not (getattr(metric, "nan_means_no_output", False) and output.size and np.isnan(output).all()):
        bad = int(output.size - np.isfinite(output).sum())
        raise SUTOutputError(
            f"the system under test returned an array of shape {output.shape} with {bad} NaN/Inf value(s) on "
            f"the {role} view ({where}); expected {expects} with finite values"
        )
