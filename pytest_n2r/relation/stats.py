"""What one relation run did: counts of accepted, rejected and undefined draws, the worst and the minimal
failing example, and where the time went."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

__all__ = ["RelationStats", "MAX_UNDEFINED", "plural"]

#: A relation fails as "the SUT produced nothing to test" when more than this share of the draws it could
#: evaluate (valid follow-up views) had an undefined metric (no keypoints, empty or all-NaN outputs, ...).
MAX_UNDEFINED = 0.5


@dataclass
class RelationStats:
    """What one relation run did: counts, the worst and the minimal failing example, the time split.

    ``examples`` counts accepted examples (valid view, defined metric) of the search; ``rejected`` the draws
    whose follow-up view was invalid, ``undefined`` those where the metric had no value (by reason);
    ``shrink_examples`` the examples Hypothesis ran while shrinking a failure. ``records`` holds one plain
    record per drawn example of the search (accepted, rejected and undefined, also after the first failure;
    see :class:`pytest_n2r.report.records.ExampleRecord`), ``replayed`` one per baseline example replayed
    before the search. Times are seconds of wall clock spent rendering (including cache lookups), in the SUT
    and in the metric.
    """

    test_id: str
    scene: str
    metric: str
    eps: float
    scene_hash: str = ""
    examples: int = 0
    rejected: Counter = field(default_factory=Counter)
    undefined: Counter = field(default_factory=Counter)
    inconsistencies: int = 0
    shrink_examples: int = 0
    worst_deviation: float = float("nan")
    worst: dict[str, Any] | None = None
    minimal: dict[str, Any] | None = None
    render_s: float = 0.0
    sut_s: float = 0.0
    metric_s: float = 0.0
    renders: int = 0
    outcome: str = "passed"
    message: str = ""
    records: list[dict[str, Any]] = field(default_factory=list)
    replayed: list[dict[str, Any]] | None = None

    @property
    def n_rejected(self) -> int:
        return sum(self.rejected.values())

    @property
    def n_undefined(self) -> int:
        return sum(self.undefined.values())

    def summary_line(self) -> str:
        worst = "n/a" if math.isnan(self.worst_deviation) else f"{self.worst_deviation:.3g}"
        rejected = f"{self.n_rejected} rejected as invalid" + _reasons(self.rejected)
        undefined = f"{self.n_undefined} undefined" + _reasons(self.undefined)
        replayed = "" if self.replayed is None else f"{len(self.replayed)} baseline examples replayed, "
        return (
            f"{self.outcome.upper():6s} {self.test_id}: {replayed}{plural(self.examples, 'example')}, {rejected}, "
            f"{undefined}, {self.inconsistencies} inconsistent, worst deviation {worst} (eps {self.eps:g}); "
            f"time render {self.render_s:.2f} s / SUT {self.sut_s:.2f} s / metric {self.metric_s:.2f} s"
        )

    def to_record(self) -> Any:
        """The plain-data :class:`pytest_n2r.report.records.RelationRecord` of this run."""
        from ..report.records import ExampleRecord, RelationRecord

        return RelationRecord(
            nodeid=self.test_id, metric=self.metric, eps=self.eps, scene=self.scene, scene_hash=self.scene_hash,
            examples=[ExampleRecord.from_dict(r) for r in self.records], outcome=self.outcome,
            message=self.message, timings={"render": self.render_s, "sut": self.sut_s, "metric": self.metric_s},
            minimal=ExampleRecord.from_dict(self.minimal) if self.minimal else None,
            replayed=None if self.replayed is None else [ExampleRecord.from_dict(r) for r in self.replayed],
        )


def plural(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _reasons(counts: Counter) -> str:
    return " (" + ", ".join(f"{n} {r}" for r, n in counts.most_common()) + ")" if counts else ""

