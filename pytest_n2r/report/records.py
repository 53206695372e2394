"""Plain-data records of relation runs (JSON-ready; no pytest, no numpy objects)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

__all__ = ["ExampleRecord", "RelationRecord", "deviation_stats", "STATS"]


@dataclass
class ExampleRecord:
    """One example of a relation: which view and transform, the metric's score and deviation.

    ``transform`` is the transform's fields (``{"yaw": 5.0, "x": 0.1, ...}``, degrees and reference lengths)
    or a mutation's description (``{"mutation": "brightness(delta=30)"}``). ``valid`` is False for an
    example rejected because the follow-up view was outside what the field can render faithfully.
    """

    scene: str
    view: str
    transform: dict[str, Any]
    score: float
    deviation: float
    passed: bool
    valid: bool = True
    images: dict[str, str] = field(default_factory=dict)

    def key(self) -> tuple:
        """Identity of the example (scene, view, transform): what a baseline comparison pairs on."""
        return (self.scene, self.view, tuple(sorted((k, _round(v)) for k, v in self.transform.items())))

    @classmethod
    def from_dict(cls, data: dict) -> "ExampleRecord":
        return cls(**{k: data[k] for k in cls.__dataclass_fields__ if k in data})


@dataclass
class RelationRecord:
    """Every example of one relation (one test id) plus its verdict and timing split (seconds)."""

    nodeid: str
    metric: str
    eps: float
    examples: list[ExampleRecord] = field(default_factory=list)
    outcome: str = "passed"
    message: str = ""
    timings: dict[str, float] = field(default_factory=dict)
    minimal: ExampleRecord | None = None
    #: The field floor beside the result (:func:`pytest_n2r.floor.annotate_relation`; ``None`` on exact scenes).
    floor: dict[str, Any] | None = None

    @property
    def valid_examples(self) -> list[ExampleRecord]:
        return [e for e in self.examples if e.valid]

    @property
    def rejected(self) -> int:
        return sum(not e.valid for e in self.examples)

    @property
    def inconsistencies(self) -> int:
        return sum(not e.passed for e in self.valid_examples)

    @property
    def worst(self) -> ExampleRecord | None:
        valid = self.valid_examples
        return max(valid, key=lambda e: e.deviation) if valid else None

    def stats(self) -> dict[str, float]:
        return deviation_stats([e.deviation for e in self.valid_examples], self.eps)

    def to_dict(self) -> dict:
        data = asdict(self)
        data["stats"] = self.stats()
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "RelationRecord":
        minimal = data.get("minimal")
        return cls(
            nodeid=data["nodeid"], metric=data["metric"], eps=float(data["eps"]),
            examples=[ExampleRecord.from_dict(e) for e in data.get("examples", [])],
            outcome=data.get("outcome", "passed"), message=data.get("message", ""),
            timings=dict(data.get("timings", {})),
            minimal=ExampleRecord.from_dict(minimal) if minimal else None, floor=data.get("floor"),
        )


#: Statistics of a relation's deviations (0 = ideal, larger = worse) that baselines compare.
STATS = ("mean", "median", "p10", "p90", "max", "rate")


def deviation_stats(deviations: list[float], eps: float) -> dict[str, float]:
    """Mean, median, 10th / 90th percentile and max of deviations, and the inconsistency rate at ``eps``.

    Percentiles use linear interpolation between order statistics. Empty input gives NaN for every
    statistic (a relation with no valid example has nothing to compare).

    >>> s = deviation_stats([0.0, 0.1, 0.2, 0.3, 0.4], eps=0.25)
    >>> s["mean"], s["p90"], s["rate"]
    (0.2, 0.36, 0.4)
    """
    if not deviations:
        return {s: math.nan for s in STATS}
    xs = sorted(float(d) for d in deviations)

    def pct(q: float) -> float:
        pos = q * (len(xs) - 1)
        lo = math.floor(pos)
        hi = min(lo + 1, len(xs) - 1)
        return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)

    return {
        "mean": min(max(math.fsum(xs) / len(xs), xs[0]), xs[-1]), "median": pct(0.5), "p10": pct(0.1), "p90": pct(0.9),
        "max": xs[-1], "rate": sum(d > eps for d in xs) / len(xs),
    }


def _round(value: Any) -> Any:
    return round(value, 9) if isinstance(value, float) else value
