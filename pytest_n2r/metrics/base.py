"""The metric interface of metamorphic relations.

A metric compares the SUT's output on the source view with its output on the follow-up view. It has a
``score`` with a known ``ideal`` value; the relation holds when the **deviation** from the ideal is at
most ``eps`` (design.md §6): repeatability 0.74 → deviation 0.26 → fails at ``eps=0.2``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

from .._validation import check_range
from ..render.view import RenderedView

__all__ = ["Metric", "MetricResult"]


@dataclass(frozen=True)
class MetricResult:
    """One evaluation: the ``score``, its ``deviation`` from the ideal, and counts that explain it
    (e.g. ``{"n_source": 100, "n_follow": 96, "n_visible": 80, "n_matched": 59}``)."""

    metric: str
    score: float
    deviation: float
    details: dict[str, Any] = field(default_factory=dict)

    def holds(self, eps: float) -> bool:
        return self.deviation <= eps


class Metric(ABC):
    """Base class of SUT metrics. Subclasses set ``name``, ``ideal`` and ``needs`` and implement
    :meth:`compute`; ``repr`` rebuilds the constructor call."""

    #: Short name used in reports (``"repeatability"``).
    name: ClassVar[str]
    #: The score of two identical outputs (1 for similarities, 0 for distances).
    ideal: ClassVar[float]
    #: Render outputs the metric needs besides what the SUT consumes (``("depth", "opacity")`` for
    #: metrics that map pixels between the two views).
    needs: ClassVar[tuple[str, ...]] = ()

    @abstractmethod
    def compute(
        self, out_source: Any, out_follow: Any, source: RenderedView | None, follow: RenderedView | None
    ) -> MetricResult:
        """Score the SUT outputs on the source and follow-up views."""

    def deviation(self, score: float) -> float:
        """Distance of ``score`` from :attr:`ideal` (``|score - ideal|``)."""
        return abs(float(score) - float(self.ideal))

    def __call__(
        self, out_source: Any, out_follow: Any, source: RenderedView | None = None,
        follow: RenderedView | None = None,
    ) -> MetricResult:
        return self.compute(out_source, out_follow, source, follow)

    def assert_within(
        self, out_source: Any, out_follow: Any, source: RenderedView | None = None,
        follow: RenderedView | None = None, *, eps: float,
    ) -> MetricResult:
        """Evaluate and raise ``AssertionError`` (score, deviation, eps, details) if deviation > eps."""
        __tracebackhide__ = True
        eps = check_range("eps", eps, 0.0)
        result = self.compute(out_source, out_follow, source, follow)
        if not result.holds(eps):
            details = ", ".join(f"{k}={v}" for k, v in result.details.items())
            raise AssertionError(
                f"{self!r}: score {result.score:.4f} deviates {result.deviation:.4f} from the ideal "
                f"{self.ideal:g}, more than eps={eps:g}" + (f" ({details})" if details else "")
            )
        return result
