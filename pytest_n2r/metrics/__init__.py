"""Metrics of metamorphic relations: SUT output agreement and image quality.

Every SUT metric is a :class:`Metric` with a ``name``, an ``ideal`` score and a ``deviation``; the
relation holds when the deviation is at most ``eps``. Build one with its factory
(``repeatability(px=2)``) or by name (``resolve_metric("repeatability", px=2)``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validation import is_finite
from ..errors import InvalidArgument, InvalidType
from .base import Metric, MetricResult
from .classification import (
    ClassInvariance,
    CosineSimilarity,
    L2Norm,
    class_invariance,
    cosine_similarity,
    l2_norm,
)
from .correspondence import DepthMapping, HomographyMapping, MappedPoints, PointMapping
from .image_quality import SSIM, lpips, psnr, ssim, ssim_metric
from .keypoints import (
    InterestPointSpread,
    KeypointCorrespondences,
    Repeatability,
    interest_point_spread,
    repeatability,
)

__all__ = [
    "Metric", "MetricResult", "METRICS", "resolve_metric",
    "cosine_similarity", "l2_norm", "class_invariance", "repeatability", "interest_point_spread", "ssim_metric",
    "CosineSimilarity", "L2Norm", "ClassInvariance", "Repeatability", "InterestPointSpread", "SSIM",
    "PointMapping", "DepthMapping", "HomographyMapping", "MappedPoints", "KeypointCorrespondences",
    "psnr", "ssim", "lpips",
]

#: Every SUT metric by its ``name``; the value is the class (its constructor takes the metric's parameters).
METRICS: dict[str, type[Metric]] = {
    cls.name: cls
    for cls in (CosineSimilarity, L2Norm, ClassInvariance, Repeatability, InterestPointSpread, SSIM)
}


def _check_declared(metric: Metric) -> None:
    """A metric of one's own must say its ``name`` (a string) and ``ideal`` (a finite number), which the engine
    reads only once it scores: refused here, naming the class, not with a bare AttributeError mid-run."""
    cls = type(metric).__qualname__
    name = getattr(metric, "name", None)
    if not isinstance(name, str) or not name:
        raise InvalidType(f"metric {cls} has name={name!r}; expected a short string used in reports, set on the "
                          "class (name = \"my_metric\")")
    ideal = getattr(metric, "ideal", None)
    if isinstance(ideal, bool) or not isinstance(ideal, (int, float, np.integer, np.floating)) or not is_finite(ideal):
        raise InvalidType(f"metric {cls} has ideal={ideal!r}; expected a finite number on the class: the score of "
                          "two identical outputs (1.0 for a similarity, 0.0 for a distance)")


def resolve_metric(metric: Metric | str, **params: Any) -> Metric:
    """A metric object from a metric (returned as is) or a name from :data:`METRICS` plus parameters.

    >>> resolve_metric("repeatability", px=3)
    repeatability(px=3.0, matching='maximum', mapping='depth')
    """
    if isinstance(metric, Metric):
        if params:
            raise InvalidArgument(f"parameters {sorted(params)} given with the metric object {metric!r}; "
                                  "pass them to its factory instead")
        _check_declared(metric)
        return metric
    if not isinstance(metric, str):
        raise InvalidType(f"metric={metric!r} must be a Metric or a metric name (e.g. repeatability(px=2) or "
                          f"'repeatability'), not {type(metric).__name__}")
    cls = METRICS.get(metric)
    if cls is None:
        raise InvalidArgument(f"unknown metric {metric!r}; known: {', '.join(sorted(METRICS))}")
    try:
        return cls(**params)
    except TypeError as exc:
        if isinstance(exc, InvalidType):
            raise
        raise InvalidArgument(f"metric {metric!r} does not take {sorted(params)}: {exc}") from None
