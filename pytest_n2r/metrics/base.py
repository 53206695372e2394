"""The metric interface of metamorphic relations.

A metric compares the SUT's output on the source view with its output on the follow-up view. It has a
``score`` with a known ``ideal`` value; the relation holds when the **deviation** from the ideal is at
most ``eps`` (docs/metrics.md, the top): repeatability 0.74 → deviation 0.26 → fails at ``eps=0.2``.
"""

from __future__ import annotations

import math
import re
import sys
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from types import BuiltinFunctionType, FunctionType
from typing import Any, ClassVar

import numpy as np

from .._validation import check_range
from ..errors import MetricUndefined
from ..render.view import RenderedView

__all__ = ["Metric", "MetricResult"]


@dataclass(frozen=True)
class MetricResult:
    """One evaluation: the ``score``, its ``deviation`` from the ideal, and counts that explain it
    (e.g. ``{"n_source": 100, "n_follow": 96, "n_visible": 80, "n_matched": 59}``).

    ``valid`` is False when the metric is undefined for this pair (e.g. no keypoint lies in the region
    both views see): then ``score`` and ``deviation`` are NaN, ``details["reason"]`` says why, and the
    pair is *not a test* -- it neither passes nor fails (:meth:`Metric.assert_within` rejects it).
    """

    metric: str
    score: float
    deviation: float
    details: dict[str, Any] = field(default_factory=dict)
    valid: bool = True

    @classmethod
    def undefined(cls, metric: str, reason: str, **details: Any) -> MetricResult:
        """A result flagged ``valid=False`` with NaN score and deviation, and ``reason`` in the details."""
        return cls(metric, math.nan, math.nan, {"reason": reason, **details}, valid=False)

    def holds(self, eps: float) -> bool:
        """True when the result is valid and its deviation is at most ``eps``."""
        return self.valid and self.deviation <= eps


class Metric(ABC):
    """Base class of SUT metrics. Subclasses set ``name``, ``ideal`` and ``needs`` and implement
    :meth:`compute`; ``repr`` rebuilds the constructor call.

    A subclass without a ``__repr__`` of its own gets :meth:`__repr__` below: its class name and public
    attributes, the same in every run (baselines compare metrics by their ``repr``)."""

    #: Short name used in reports (``"repeatability"``).
    name: ClassVar[str]
    #: The score of two identical outputs (1 for similarities, 0 for distances).
    ideal: ClassVar[float]
    #: Render outputs the metric needs besides what the SUT consumes (``("depth", "opacity")`` for
    #: metrics that map pixels between the two views). An instance may override it when its parameters
    #: decide (``repeatability(mapping="homography")`` needs no depth).
    needs: tuple[str, ...] = ()
    #: True when an output that is entirely NaN means "the SUT gave no answer" (the pair is undefined)
    #: rather than a bug (a :class:`~pytest_n2r.errors.SUTOutputError`).
    nan_means_no_output: ClassVar[bool] = False
    #: The version of the metric's arithmetic, declared by a metric class whose result depends on nothing but
    #: its ``repr`` (every parameter), the two SUT outputs and the two renders, and costs more to compute than to
    #: read back: a render cache then keeps its results across sessions
    #: (:mod:`~pytest_n2r.relation.kept_results`). Bump it when the arithmetic changes. Only the class that
    #: declares it is kept, not its subclasses; ``None``: always computed.
    result_version: ClassVar[str | None] = None

    @abstractmethod
    def compute(
        self, out_source: Any, out_follow: Any, source: RenderedView | None, follow: RenderedView | None
    ) -> MetricResult:
        """Score the SUT outputs on the source and follow-up views."""

    def __repr__(self) -> str:
        """``MyMetric(a=1, b='x')``: the class's qualified name and its public instance attributes, sorted by name,
        with no memory address, so an unchanged metric has the same ``repr`` in every run (a baseline compares
        metrics by it: ``changed-metric``, and the field floor and kept results are keyed by it). A subclass whose
        constructor parameters are stored under other names should define its own ``repr``.

        >>> class Diff(Metric):
        ...     name, ideal = "diff", 0.0
        ...     def __init__(self, scale=1.0):
        ...         self.scale, self._cache = scale, {}
        ...     def compute(self, a, b, source=None, follow=None):
        ...         return self.result(abs(a - b) * self.scale)
        >>> Diff(2.0)
        Diff(scale=2.0)
        """
        attrs = sorted((k, v) for k, v in vars(self).items() if not k.startswith("_"))
        return f"{type(self).__qualname__}({', '.join(f'{k}={_stable_repr(v)}' for k, v in attrs)})"

    def deviation(self, score: float) -> float:
        """Distance of ``score`` from :attr:`ideal` (``|score - ideal|``)."""
        return abs(float(score) - float(self.ideal))

    def result(self, score: float, **details: Any) -> MetricResult:
        """A valid :class:`MetricResult` of this metric for ``score`` (deviation computed here)."""
        score = float(score)
        return MetricResult(self.name, score, self.deviation(score), details)

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
        if not result.valid:
            _reject(f"{self!r} is undefined for this pair: {result.details.get('reason', 'no reason given')}")
        if not result.holds(eps):
            details = ", ".join(f"{k}={v}" for k, v in result.details.items())
            raise AssertionError(
                f"{self!r}: score {result.score:.4f} deviates {result.deviation:.4f} from the ideal "
                f"{self.ideal:g}, more than eps={eps:g}" + (f" ({details})" if details else "")
            )
        return result


#: `` at 0x7f...``: the memory address in a default ``repr``, which differs from run to run.
_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")


def _stable_repr(value: Any) -> str:
    """``repr(value)`` without what changes between runs: a function or class by its qualified name, an array by
    its values (numpy's ``repr`` elides long ones), and no memory address."""
    if isinstance(value, (type, FunctionType, BuiltinFunctionType)):
        return f"{getattr(value, '__module__', '?')}.{value.__qualname__}"
    if isinstance(value, np.ndarray):
        return f"array({value.tolist()!r}, dtype={str(value.dtype)!r})"
    if isinstance(value, (list, tuple)):
        items = ", ".join(_stable_repr(v) for v in value)
        return f"[{items}]" if isinstance(value, list) else f"({items}{',' if len(value) == 1 else ''})"
    if isinstance(value, (set, frozenset)):  # in the order of their items' words, not of their hashes
        return "{" + ", ".join(sorted(_stable_repr(v) for v in value)) + "}"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_stable_repr(k)}: {_stable_repr(v)}" for k, v in value.items()) + "}"
    return _ADDRESS.sub("", repr(value))


def _reject(message: str) -> None:
    """Reject the current Hypothesis example (the pair tests nothing), or raise :class:`MetricUndefined`
    outside Hypothesis. Hypothesis is only consulted if the caller already imported it."""
    __tracebackhide__ = True
    hypothesis = sys.modules.get("hypothesis")
    if hypothesis is not None and hypothesis.currently_in_test_context():
        hypothesis.reject()
    raise MetricUndefined(message)
