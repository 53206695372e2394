"""Small exact metrics for plugin tests (the real ones live in pytest_n2r.metrics)."""

from __future__ import annotations

from typing import Any

import numpy as np

from pytest_n2r.errors import InvalidType
from pytest_n2r.metrics.base import Metric, MetricResult


class SameLabel(Metric):
    """Score 1 when both outputs are the same label, else 0 (ideal 1)."""

    name = "same_label"
    ideal = 1.0
    expects = "a class label (int or str)"

    def compute(self, out_source: Any, out_follow: Any, source: Any, follow: Any) -> MetricResult:
        if not isinstance(out_source, (int, str, np.integer)) or not isinstance(out_follow, (int, str, np.integer)):
            raise InvalidType(f"same_label compares class labels (int or str), got {type(out_follow).__name__}")
        score = float(out_source == out_follow)
        return MetricResult(self.name, score, self.deviation(score), {"source": out_source, "follow": out_follow})

    def __repr__(self) -> str:
        return "SameLabel()"


class AbsDifference(Metric):
    """``|a - b|`` of two scalar outputs (ideal 0)."""

    name = "abs_difference"
    ideal = 0.0

    def compute(self, out_source: Any, out_follow: Any, source: Any, follow: Any) -> MetricResult:
        score = abs(float(out_source) - float(out_follow))
        return MetricResult(self.name, score, self.deviation(score))

    def __repr__(self) -> str:
        return "AbsDifference()"
