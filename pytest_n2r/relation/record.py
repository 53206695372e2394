"""The records of relation runs: what the engine writes, and what the plugin, baselines, JSON, JUnit and HTML
read (plain, JSON-ready data: no pytest, no numpy objects).

One :class:`ExampleRecord` per drawn example -- accepted, rejected (invalid follow-up view) or undefined
(the metric had no value, e.g. the SUT found no keypoint) -- with everything needed to replay it bit for
bit: the scene's content hash, the source view's name, pose and camera (render size), the render
settings, and the follow-up (a pose transform with its units, or a mutation with its parameters).
A :class:`RelationRecord` is one relation run: every example it drew, the baseline examples it replayed,
its verdict, where the time went and, on fitted scenes, its ``floor`` (the deviation the scene field alone
causes, :mod:`pytest_n2r.relation.floor`).
"""

from __future__ import annotations

import copy
import math
from collections import Counter
from dataclasses import dataclass, field, fields
from typing import Any

__all__ = ["ExampleRecord", "RelationRecord", "deviation_stats", "STATS", "STATUSES", "TIMINGS", "MORE_TIMINGS",
           "plural"]

#: What happened to a drawn example.
STATUSES = ("accepted", "rejected", "undefined")


@dataclass
class ExampleRecord:
    """One drawn example of a relation.

    ``transform`` is a pose transform's fields (``{"yaw": 5.0, "x": 0.1, ...}``, degrees, translations in
    ``units``), or ``None`` when the follow-up is a ``mutation`` (``{"name": "brightness", "levels": 30}``).
    ``status`` is ``"accepted"`` (a test: ``score``, ``deviation`` and ``passed`` are set), ``"rejected"``
    (the follow-up view was outside what the scene renders faithfully) or ``"undefined"`` (the metric had
    no value); ``reason`` says why for the last two (score and deviation are then NaN). ``scene_hash``,
    ``source_c2w`` (16 floats, row-major camera-to-world, OpenCV axes), ``camera``
    (:meth:`~pytest_n2r.geometry.Camera.to_dict`, the render size included) and ``settings`` (the scene's
    render settings) make the example replayable exactly.
    """

    scene: str
    view: str
    transform: dict[str, Any] | None
    score: float
    deviation: float
    passed: bool
    status: str = "accepted"
    reason: str = ""
    scene_hash: str = ""
    source_c2w: list[float] = field(default_factory=list)
    camera: dict[str, Any] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    units: str = "reference"
    mutation: dict[str, Any] | None = None
    images: dict[str, str] = field(default_factory=dict)

    @property
    def valid(self) -> bool:
        """True for an accepted example (one that tested the SUT)."""
        return self.status == "accepted"

    def key(self) -> tuple:
        """Identity of the example: scene content, source pose and camera, follow-up."""
        follow = self.transform if self.mutation is None else self.mutation
        return (self.scene_hash, self.view, tuple(_round(v) for v in self.source_c2w),
                tuple(sorted((k, _round(v)) for k, v in self.camera.items() if k != "distortion")), self.units,
                tuple(sorted((k, _round(v)) for k, v in (follow or {}).items())))

    @property
    def replayable(self) -> bool:
        """Whether the record holds all a replay needs (a source pose, a camera and a rebuildable follow-up)."""
        return len(self.source_c2w) == 16 and bool(self.camera) and (
            self.transform is not None or (self.mutation is not None and "name" in self.mutation))

    def follow_up(self) -> Any:
        """The follow-up as an object (:class:`~pytest_n2r.strategies.FollowUp`): a
        :class:`~pytest_n2r.strategies.PoseChange` in the recorded ``units``, or a mutation."""
        if self.mutation is not None:
            from ..strategies.mutation import mutation_from_dict

            return mutation_from_dict(self.mutation)
        from .._validation import check_choice
        from ..geometry import Units
        from ..strategies.pose_change import PoseChange

        return PoseChange(**(self.transform or {}), units=check_choice("units", self.units, Units, "a unit"))

    @classmethod
    def from_dict(cls, data: dict) -> ExampleRecord:
        """The record of a plain dict (unknown keys ignored); ``valid=False`` in old data means rejected."""
        data = dict(data)
        if "status" not in data and data.get("valid") is False:
            data["status"] = "rejected"
        return cls(**{k: data[k] for k in cls.__dataclass_fields__ if k in data})

    def to_dict(self) -> dict[str, Any]:
        return _plain(self)


#: The parts of a relation run's wall-clock time (seconds): rendering (cache lookups included), the SUT, the metric.
TIMINGS = ("render", "sut", "metric")
#: More of a run's clock (seconds), kept beside :data:`TIMINGS`: the validity checks, the whole run (``total``:
#: the search, its Hypothesis bookkeeping and the parts above) and the annotations the plugin adds afterwards
#: (``floor``: the field floor and the exact-twin replay, 0 on exact scenes).
MORE_TIMINGS = ("validity", "total", "floor")


@dataclass
class RelationRecord:
    """One relation run (one test id): every example the search drew (:attr:`examples`, in draw order,
    also after the first failure), its verdict and the time split (:data:`TIMINGS` and :data:`MORE_TIMINGS`,
    seconds).

    ``replayed`` holds the baseline examples replayed before the search (``None`` when none were asked
    for); ``minimal`` the minimal failing example after shrinking (with its saved ``images``); ``renders``
    the renders that missed the cache, ``sut_calls`` the calls of the SUT and ``sut_shared`` the outputs taken
    from an earlier call on the same render (:mod:`pytest_n2r.relation.sut_outputs`),
    ``shrink_examples`` the examples Hypothesis ran while shrinking a failure. ``floor`` is the plain dict of
    the field-floor measurement beside the result (``None`` when none was made); reports show its ``line``
    beside the relation's deviations.
    """

    nodeid: str
    metric: str
    eps: float
    examples: list[ExampleRecord] = field(default_factory=list)
    outcome: str = "passed"
    message: str = ""
    timings: dict[str, float] = field(default_factory=dict)
    minimal: ExampleRecord | None = None
    scene: str = ""
    scene_hash: str = ""
    replayed: list[ExampleRecord] | None = None
    #: The field floor beside the result (:func:`pytest_n2r.relation.floor.annotate_relation`; ``None`` on an
    #: exact scene).
    floor: dict[str, Any] | None = None
    renders: int = 0
    sut_calls: int = 0
    sut_shared: int = 0
    shrink_examples: int = 0
    #: The examples the search was asked for (0: not known, e.g. an older record).
    asked: int = 0
    #: pytest's final outcome of the test (``passed``, ``failed``, ``error``, ``xfailed``, ``xpassed``; a strict
    #: xfail's pass is ``failed``), set by the plugin; ``""`` outside pytest. :attr:`outcome` stays the relation's
    #: own verdict (baselines and comparisons read it).
    pytest_outcome: str = ""

    @property
    def valid_examples(self) -> list[ExampleRecord]:
        """The accepted examples: those that tested the SUT."""
        return [e for e in self.examples if e.valid]

    @property
    def rejected(self) -> int:
        return sum(e.status == "rejected" for e in self.examples)

    @property
    def undefined(self) -> int:
        return sum(e.status == "undefined" for e in self.examples)

    @property
    def rejected_reasons(self) -> Counter:
        """Rejected examples by reason (``"empty view"``, ``"outside the captured region"``)."""
        return Counter(e.reason for e in self.examples if e.status == "rejected")

    @property
    def undefined_reasons(self) -> Counter:
        """Undefined examples by the metric's reason (``"the SUT found no keypoint in either view"``, ...)."""
        return Counter(e.reason for e in self.examples if e.status == "undefined")

    @property
    def inconsistencies(self) -> int:
        return sum(not e.passed for e in self.valid_examples)

    @property
    def worst(self) -> ExampleRecord | None:
        """The accepted example of the largest deviation (the first of equals), ``None`` without one."""
        valid = self.valid_examples
        return max(valid, key=lambda e: e.deviation) if valid else None

    @property
    def worst_deviation(self) -> float:
        worst = self.worst
        return math.nan if worst is None else worst.deviation

    def stats(self) -> dict[str, float]:
        return deviation_stats([e.deviation for e in self.valid_examples], self.eps)

    def summary_line(self) -> str:
        """One line for the terminal: outcome, test id, counts (with reasons), worst deviation, time split."""
        worst = "n/a" if math.isnan(self.worst_deviation) else f"{self.worst_deviation:.3g}"
        rejected = f"{self.rejected} rejected as invalid" + _reasons(self.rejected_reasons)
        undefined = f"{self.undefined} undefined" + _reasons(self.undefined_reasons)
        replayed = "" if self.replayed is None else f"{len(self.replayed)} baseline examples replayed, "
        render, sut, metric = (self.timings.get(k, 0.0) for k in TIMINGS)
        total = self.timings.get("total", 0.0) + self.timings.get("floor", 0.0)
        shown = len(self.valid_examples)
        fewer = (f" ({self.asked} asked: the search found no more distinct ones)"
                 if self.outcome == "passed" and 0 < shown < self.asked else "")
        return (
            f"{self.outcome.upper():6s} {self.nodeid}: {replayed}{plural(shown, 'example')}{fewer}, "
            f"{rejected}, {undefined}, {self.inconsistencies} inconsistent, worst deviation {worst} (eps "
            f"{self.eps:g}); time render {render:.2f} s / SUT {sut:.2f} s / metric {metric:.2f} s"
            + (f" of {total:.2f} s" if total else "")
        )

    def to_dict(self) -> dict:
        data = _plain(self)
        data["stats"] = self.stats()
        return data

    @classmethod
    def from_dict(cls, data: dict) -> RelationRecord:
        minimal, replayed = data.get("minimal"), data.get("replayed")
        return cls(
            nodeid=data["nodeid"], metric=data["metric"], eps=float(data["eps"]),
            examples=[ExampleRecord.from_dict(e) for e in data.get("examples", [])],
            outcome=data.get("outcome", "passed"), message=data.get("message", ""),
            timings=dict(data.get("timings", {})),
            minimal=ExampleRecord.from_dict(minimal) if minimal else None,
            scene=data.get("scene", ""), scene_hash=data.get("scene_hash", ""),
            replayed=None if replayed is None else [ExampleRecord.from_dict(e) for e in replayed],
            floor=data.get("floor"), renders=int(data.get("renders", 0)),
            sut_calls=int(data.get("sut_calls", 0)), sut_shared=int(data.get("sut_shared", 0)),
            shrink_examples=int(data.get("shrink_examples", 0)), asked=int(data.get("asked", 0)),
            pytest_outcome=str(data.get("pytest_outcome", "")),
        )


def plural(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _reasons(counts: Counter) -> str:
    return " (" + ", ".join(f"{n} {r}" for r, n in counts.most_common()) + ")" if counts else ""


#: Statistics of a relation's deviations (0 = ideal, larger = worse) that reports show.
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


#: Leaves :func:`_plain` keeps as they are (immutable), where ``dataclasses.asdict`` deep-copies each.
_IMMUTABLE = (str, int, float, bool, type(None))


def _plain(value: Any) -> Any:
    """``dataclasses.asdict`` of a record, to the same dict, in a quarter of its time (a relation's record is
    converted once per test: pytest-xdist ships it as a dict): dataclasses, dicts, lists and tuples copied,
    the immutable leaves kept, anything else (a ``Counter``, an array) deep-copied.

    >>> _plain(ExampleRecord("s", "v", {"yaw": 1.0}, 0.5, 0.5, True, camera={"k": [1.0, 2.0]}))["camera"]
    {'k': [1.0, 2.0]}
    """
    if isinstance(value, _IMMUTABLE):
        return value
    if isinstance(value, (ExampleRecord, RelationRecord)):
        return {f.name: _plain(getattr(value, f.name)) for f in fields(value)}
    if type(value) is dict:
        return {_plain(k): _plain(v) for k, v in value.items()}
    if type(value) is list:
        return [_plain(v) for v in value]
    if type(value) is tuple:
        return tuple(_plain(v) for v in value)
    return copy.deepcopy(value)


def _round(value: Any) -> Any:
    return round(value, 9) if isinstance(value, float) else value

