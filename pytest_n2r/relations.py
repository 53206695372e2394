"""The metamorphic relation engine: render a source and a follow-up view, run the SUT on both, compare.

No pytest here: the plugin (and anyone else) calls :func:`check_relation` with a scene, a SUT and a
:class:`Relation`, and gets a :class:`RelationStats` back or a :class:`RelationFailure` (an
``AssertionError``) whose message states the scene, the source view, the minimal transform, the metric's
score and deviation, ``eps`` and where the failure pictures are.

Hypothesis drives the search: it draws a source view and a transform, shrinks a failure to the smallest
transform that still fails, replays the last failure first from its example database, seeds from the
relation's identity when ``derandomize`` is on, and with ``search="targeted"`` steers toward larger
deviations with :func:`hypothesis.target`. Deadlines are off and the "too slow" / "filters too much"
health checks are suppressed, because renders are slow and invalid views are expected; a real hang is
caught by the per-call time limit instead (:mod:`pytest_n2r._timeout`).
"""

from __future__ import annotations

import math
import os
import random
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, Phase, assume, given, target
from hypothesis import seed as hypothesis_seed
from hypothesis import settings as hsettings
from hypothesis import strategies as st
from hypothesis.database import ReadOnlyDatabase
from hypothesis.errors import Flaky, Unsatisfiable

from ._determinism import NotDeterministic, SUTNotDeterministic, same_output, show_output
from ._timeout import TimeLimitReached, time_limit
from ._validation import check_range
from .artifacts import artifact_dir, save_pair
from .cache import RenderCache
from .errors import InvalidArgument, InvalidType, MetricUndefined, N2RError, SUTOutputError
from .geometry import Camera, Transform, Units
from .metrics.base import Metric, MetricResult
from .render.size import RenderSize
from .render.view import RenderedView
from .scene.base import Scene, SceneView, normalize_outputs
from .strategies import PRESETS, SPLITS, interpolate_view, scene_views, transform_units
from .validity import Validity

__all__ = ["Relation", "RunSettings", "RelationStats", "RelationFailure", "SUTError", "check_relation",
           "resolve_metric", "SEARCHES", "MAX_UNDEFINED", "replay_relation"]

SEARCHES = ("random", "targeted")


class RelationFailure(AssertionError):
    """The SUT's outputs on a source view and its follow-up deviate by more than ``eps``."""

    def __init__(self, message: str, stats: RelationStats | None = None):
        super().__init__(message)
        self.stats = stats


#: Give up on a relation once this many draws were invalid and they are more than ``max_rejected`` of all.
_MIN_REJECTED_TO_GIVE_UP = 40


class SUTError(N2RError):
    """The system under test raised; the original exception is chained (``__cause__``)."""


# -- the relation ---------------------------------------------------------------------------------------


def resolve_metric(metric: Any) -> Metric:
    """A :class:`Metric` instance, or a metric's name (``"repeatability"``) built with its defaults
    (:data:`pytest_n2r.metrics.METRICS` lists the names)."""
    from . import metrics

    if isinstance(metric, Metric):
        return metric
    if isinstance(metric, str):
        if metric not in metrics.METRICS:
            known = ", ".join(sorted(metrics.METRICS))
            raise InvalidArgument(f"metric={metric!r} is not a known metric; known names: {known}")
        return metrics.resolve_metric(metric)
    raise InvalidType(
        f"metric={metric!r} must be a pytest_n2r.metrics.Metric (e.g. repeatability(px=2)) or a metric name, "
        f"not {type(metric).__name__}"
    )


def _resolve_transform(transform: Any) -> st.SearchStrategy:
    if isinstance(transform, str):
        if transform not in PRESETS:
            raise InvalidArgument(f"transform={transform!r} is not a preset; presets: {', '.join(PRESETS)}")
        return PRESETS[transform]
    if isinstance(transform, Transform):
        return st.just(transform)
    if isinstance(transform, st.SearchStrategy):
        return transform
    raise InvalidType(
        f"transform={transform!r} must be a strategy such as transforms(yaw=10), a preset name ('tau1' to "
        f"'tau6'), a mutation strategy or a fixed Transform, not {type(transform).__name__}"
    )


@dataclass(frozen=True)
class Relation:
    """A metamorphic relation: ``metric`` deviation at most ``eps`` between the SUT's outputs on a source
    view and on its follow-up under ``transform``. ``examples``, ``size`` (``None``: the run's setting),
    ``search`` (``"random"`` or ``"targeted"``), the source ``views`` split (``"heldout"``, ``"train"``,
    ``"all"``), ``interpolate`` (sources between captured poses) and the ``validity`` thresholds.

    Build it with :meth:`build`, which validates every argument and names the bad one.
    """

    metric: Metric
    eps: float
    transform: st.SearchStrategy
    examples: int | None = None
    size: RenderSize | None = None
    search: str = "random"
    views: str = "heldout"
    interpolate: bool = False
    validity: Validity = field(default_factory=Validity)

    @classmethod
    def build(cls, metric: Any, eps: Any, transform: Any, *, examples: int | None = None,
              size: Any = None, search: str = "random", views: str = "heldout", interpolate: bool = False,
              validity: Validity | None = None) -> Relation:
        metric = resolve_metric(metric)
        try:
            eps = check_range("eps", eps, 0.0)
        except InvalidType:
            raise InvalidType(f"eps={eps!r} must be a number >= 0 (the largest allowed deviation)") from None
        except InvalidArgument:
            raise InvalidArgument(
                f"eps={eps!r} must be a finite number >= 0 (the largest allowed deviation of "
                f"{metric.name} from its ideal {metric.ideal:g})"
            ) from None
        strategy = _resolve_transform(transform)
        if examples is not None and (isinstance(examples, bool) or not isinstance(examples, int) or examples < 1):
            raise InvalidArgument(f"examples={examples!r} must be a whole number >= 1")
        if search not in SEARCHES:
            raise InvalidArgument(f"search={search!r}; expected one of {SEARCHES}")
        if views not in SPLITS:
            raise InvalidArgument(f"views={views!r}; expected one of {SPLITS}")
        if not isinstance(interpolate, bool):
            raise InvalidType(f"interpolate={interpolate!r} must be True or False")
        if validity is not None and not isinstance(validity, Validity):
            raise InvalidType(f"validity={validity!r} must be a pytest_n2r.validity.Validity")
        return cls(metric, eps, strategy, examples, None if size is None else RenderSize.parse(size),
                   search, views, interpolate, validity or Validity())

    def describe(self) -> str:
        return f"{self.metric!r} within eps={self.eps:g} under {self.transform!r}"


@dataclass(frozen=True)
class RunSettings:
    """How to run relations: defaults for ``examples`` and ``size`` (a relation's own values win),
    ``derandomize`` (same examples every run: for CI), ``timeout`` seconds per render / SUT call
    (``None``: no limit), where failure pictures go (``artifacts``; ``None``: nowhere) and the Hypothesis
    example ``database`` (``"default"``: Hypothesis's own setting)."""

    examples: int = 50
    size: RenderSize | None = None
    derandomize: bool = False
    timeout: float | None = 300.0
    artifacts: Path | None = None
    database: Any = "default"


# -- statistics -----------------------------------------------------------------------------------------

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
            f"{self.outcome.upper():6s} {self.test_id}: {replayed}{_plural(self.examples, 'example')}, {rejected}, "
            f"{undefined}, {self.inconsistencies} inconsistent, worst deviation {worst} (eps {self.eps:g}); "
            f"time render {self.render_s:.2f} s / SUT {self.sut_s:.2f} s / metric {self.metric_s:.2f} s"
        )

    def to_record(self) -> Any:
        """The plain-data :class:`pytest_n2r.report.records.RelationRecord` of this run."""
        from .report.records import ExampleRecord, RelationRecord

        return RelationRecord(
            nodeid=self.test_id, metric=self.metric, eps=self.eps, scene=self.scene, scene_hash=self.scene_hash,
            examples=[ExampleRecord.from_dict(r) for r in self.records], outcome=self.outcome,
            message=self.message, timings={"render": self.render_s, "sut": self.sut_s, "metric": self.metric_s},
            minimal=ExampleRecord.from_dict(self.minimal) if self.minimal else None,
            replayed=None if self.replayed is None else [ExampleRecord.from_dict(r) for r in self.replayed],
        )


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _reasons(counts: Counter) -> str:
    return " (" + ", ".join(f"{n} {r}" for r, n in counts.most_common()) + ")" if counts else ""


# -- the engine -----------------------------------------------------------------------------------------


def _is_final_example() -> bool:
    """True while Hypothesis replays the minimal failing example for the last time."""
    from hypothesis.errors import InvalidArgument

    try:
        from hypothesis.control import current_build_context

        return bool(current_build_context().is_final)
    # InvalidArgument: outside a Hypothesis test (no build context); ImportError/AttributeError: its internals
    # moved. Either way every example is treated as final.
    except (InvalidArgument, ImportError, AttributeError):
        return True


def _mutation_like(value: Any) -> bool:
    return not isinstance(value, Transform) and callable(getattr(value, "apply", None)) \
        and callable(getattr(value, "describe", None))


@dataclass
class _Evaluation:
    """One drawn example evaluated: its plain record and what a failure report needs."""

    record: dict[str, Any]
    where: str = ""
    result: MetricResult | None = None
    source: RenderedView | None = None
    follow: RenderedView | None = None
    outputs: tuple[Any, Any] = (None, None)


class _Engine:
    """One relation on one scene with one SUT: evaluates drawn (or replayed) examples.

    The search runs in two passes that draw the same examples (same seed): the *survey* records every
    draw and never raises, so a relation's records cover all its examples, not just those up to the first
    failure; only when the survey saw a failure does the *shrink* pass run, raising at the first failure so
    Hypothesis shrinks it to the smallest transform."""

    def __init__(self, scene: Scene, sut: Callable[[np.ndarray], Any], relation: Relation,
                 settings: RunSettings, cache: RenderCache, stats: RelationStats):
        self.scene, self.sut, self.relation, self.settings = scene, sut, relation, settings
        self.cache, self.stats = cache, stats
        self.metric = relation.metric
        self.size = relation.size or settings.size
        self.units = transform_units(relation.transform)
        needs = tuple(getattr(self.metric, "needs", ()) or ())
        self.outputs = normalize_outputs(("rgb", *needs, *(("opacity",) if relation.validity.outputs else ())))
        self.follow_outputs = normalize_outputs(("rgb", *needs, *relation.validity.outputs))
        self.source_outputs_cache: dict[str, Any] = {}
        render_settings = getattr(scene, "settings", None)
        self.render_settings = render_settings.to_dict() if callable(getattr(render_settings, "to_dict", None)) \
            else {}
        self.shrinking = False  # False: the survey pass; True: the shrink pass
        self.failed = False
        self.gave_up = ""  # why the survey stopped drawing early ("" while it goes on)
        self.images_error: str | None = None

    # -- pieces -----------------------------------------------------------------------------------------

    def camera_for(self, view: SceneView):
        return view.camera if self.size is None else self.size.apply(view.camera)

    def render(self, c2w: np.ndarray, camera: Any, view: SceneView, outputs: tuple[str, ...],
               role: str) -> RenderedView:
        start = time.perf_counter()
        renders = self.cache.stats.renders
        with time_limit(self.settings.timeout, f"rendering the {role} view of {view.name!r}",
                        escape=True):
            rendered = self.cache.render(self.scene, c2w, camera, outputs)
        self.stats.render_s += time.perf_counter() - start
        self.stats.renders += self.cache.stats.renders - renders
        return rendered

    def run_sut(self, rgb: np.ndarray, role: str, where: str) -> Any:
        start = time.perf_counter()
        try:
            with time_limit(self.settings.timeout, f"the system under test on the {role} view ({where})",
                            escape=True):
                output = self.sut(rgb)
        except Exception as exc:
            raise SUTError(
                f"the system under test raised {type(exc).__name__}: {exc} -- on the {role} view ({where}); "
                "its traceback is above"
            ) from exc
        finally:
            self.stats.sut_s += time.perf_counter() - start
        _check_output(output, role, where, self.metric)
        return output

    def compute(self, out_source: Any, out_follow: Any, source: RenderedView, follow: RenderedView,
                where: str) -> MetricResult:
        start = time.perf_counter()
        try:
            result = self.metric.compute(out_source, out_follow, source, follow)
        except MetricUndefined as exc:  # the pair tests nothing (e.g. no keypoint in the common region)
            return MetricResult.undefined(self.metric.name, str(exc))
        except (InvalidType, InvalidArgument) as exc:
            if isinstance(exc, SUTOutputError):
                raise
            raise SUTOutputError(f"{self.metric!r} cannot use the SUT's output ({where}): {exc}") from exc
        finally:
            self.stats.metric_s += time.perf_counter() - start
        if not isinstance(result, MetricResult):
            raise InvalidType(f"{self.metric!r}.compute returned {type(result).__name__}, not a MetricResult")
        if getattr(result, "valid", True) and not math.isfinite(result.deviation):
            raise SUTOutputError(
                f"{self.metric!r} gave deviation {result.deviation} ({where}); the SUT's output probably "
                "contains NaN or Inf"
            )
        return result

    # -- one example ------------------------------------------------------------------------------------

    def follow_up(self, tau: Any, units: Units) -> dict[str, Any]:
        """The follow-up of a record: a pose transform's fields and units, or a mutation's parameters."""
        if not _mutation_like(tau):
            return {"transform": tau.as_dict(), "units": units.value}
        as_dict = getattr(tau, "as_dict", None)
        return {"transform": None, "mutation": as_dict() if callable(as_dict) else {"description": tau.describe()}}

    def evaluate(self, view: SceneView, tau: Any, camera: Any = None, units: Units | None = None) -> _Evaluation:
        """Render, check validity, run the SUT and the metric on one example; never raises on a verdict.

        ``camera`` and ``units`` (a replayed example's recorded ones) override the run's render size and the
        relation's translation units."""
        camera = camera if camera is not None else self.camera_for(view)
        units = units or self.units
        mutation = _mutation_like(tau)
        describe = tau.describe() if mutation else self.describe_transform(tau)
        where = f"scene {self.scene.name!r}, source view {view.name!r}, {describe}"
        record: dict[str, Any] = {
            "scene": self.scene.name, "scene_hash": self.scene.content_hash, "view": view.name,
            "source_c2w": np.asarray(view.c2w, dtype=np.float64).ravel().tolist(), "camera": camera.to_dict(),
            "settings": self.render_settings, **self.follow_up(tau, units), "status": "accepted", "reason": "",
            "score": math.nan, "deviation": math.nan, "passed": False,
        }
        source = self.render(view.c2w, camera, view, self.outputs, "source")
        if mutation:  # the follow-up is the mutated source render, same pose
            apply_to_view = getattr(tau, "apply_to_view", None)
            follow = apply_to_view(source) if callable(apply_to_view) else RenderedView(
                camera=source.camera, c2w=source.c2w, rgb=tau.apply(source.rgb), depth=source.depth,
                opacity=source.opacity)
        else:
            follow_c2w = tau.apply(view.c2w, self.scene.length_scale(units))
            follow = self.render(follow_c2w, camera, view, self.follow_outputs, "follow-up")
            verdict = self.relation.validity.check(follow, self.scene, source)
            if not verdict.valid:
                record.update(status="rejected", reason=verdict.reason)
                return _Evaluation(record, where)
        key = f"{view.name}|{camera.width}x{camera.height}|{record['source_c2w']}"
        if key not in self.source_outputs_cache:  # the SUT runs once per source view and size
            self.source_outputs_cache[key] = self.run_sut(source.rgb, "source", where)
        out_source = self.source_outputs_cache[key]
        out_follow = self.run_sut(follow.rgb, "follow-up", where)
        result = self.compute(out_source, out_follow, source, follow, where)
        if not getattr(result, "valid", True):
            record.update(status="undefined", reason=str(result.details.get("reason", "metric undefined")))
        else:
            deviation = float(result.deviation)
            record.update(score=float(result.score), deviation=deviation, passed=deviation <= self.relation.eps)
        return _Evaluation(record, where, result, source, follow, (out_source, out_follow))

    def count(self, record: dict[str, Any]) -> None:
        """Count a survey record and stop drawing when almost every draw is invalid or undefined."""
        stats = self.stats
        stats.records.append(record)
        if record["status"] == "rejected":
            stats.rejected[record["reason"]] += 1
        elif record["status"] == "undefined":
            stats.undefined[record["reason"]] += 1
        else:
            stats.examples += 1
            if not record["deviation"] <= stats.worst_deviation:  # also true for the first (NaN)
                stats.worst_deviation, stats.worst = record["deviation"], record
            if not record["passed"]:
                stats.inconsistencies += 1
        drawn = stats.examples + stats.n_rejected + stats.n_undefined
        if stats.n_rejected >= _MIN_REJECTED_TO_GIVE_UP \
                and stats.n_rejected / drawn > self.relation.validity.max_rejected:
            self.gave_up = "invalid"  # check_relation raises once Hypothesis stops
        evaluated = stats.examples + stats.n_undefined
        if stats.n_undefined >= min(_MIN_REJECTED_TO_GIVE_UP, self.relation.examples or self.settings.examples) \
                and stats.n_undefined / evaluated > MAX_UNDEFINED:
            self.gave_up = "undefined"

    def example(self, view: SceneView, tau: Any) -> None:
        """The body of one Hypothesis example (survey or shrink pass)."""
        __tracebackhide__ = True
        if self.gave_up:  # reject the rest of the draws without rendering them
            assume(False)
        evaluation = self.evaluate(view, tau)
        record = evaluation.record
        if not self.shrinking:
            if record["status"] == "accepted" and not record["passed"] and not self.stats.inconsistencies:
                self.check_deterministic(evaluation.source.rgb, evaluation.follow.rgb, *evaluation.outputs,
                                         evaluation.where)
            self.count(record)
        elif self.failed:
            self.stats.shrink_examples += 1
        if record["status"] != "accepted":
            assume(False)  # not a test: Hypothesis draws another
        if self.relation.search == "targeted":
            target(record["deviation"], label="deviation")
        if record["passed"] or not self.shrinking:
            return
        self.failed = True
        if not _is_final_example():
            raise RelationFailure("inconsistent (shrinking)")
        self.fail(view, tau, evaluation)

    def fail(self, view: SceneView, tau: Any, evaluation: _Evaluation, note: str = "") -> None:
        """Save the failure pictures and raise the :class:`RelationFailure` of ``evaluation``."""
        __tracebackhide__ = True
        record, stats = dict(evaluation.record), self.stats
        if self.settings.artifacts is not None:
            try:
                record["images"] = save_pair(artifact_dir(self.settings.artifacts, stats.test_id),
                                             evaluation.source.rgb, evaluation.follow.rgb, *evaluation.outputs)
            except OSError as exc:  # a full disk or a read-only folder must not hide the failure itself
                self.images_error = f"not saved ({exc.strerror or exc}: {exc.filename or self.settings.artifacts})"
        stats.minimal = record
        raise RelationFailure(self.failure_message(view, tau, evaluation.result, record, note), stats)

    def check_deterministic(self, source_rgb: np.ndarray, follow_rgb: np.ndarray, out_source: Any,
                            out_follow: Any, where: str) -> None:
        """Before the first failure counts: the SUT must give the same outputs again on the same two images
        (else the failure is its noise, and Hypothesis's replay would fail at random)."""
        for role, rgb, first in (("source", source_rgb, out_source), ("follow-up", follow_rgb, out_follow)):
            again = self.run_sut(rgb, role, where)
            if not same_output(first, again):
                raise NotDeterministic(
                    f"the system under test is not deterministic: called twice on the same {role} image "
                    f"({where}) it returned\n  first:  {show_output(first, again)}\n  second: "
                    f"{show_output(again, first)}\nA relation cannot tell its noise from an inconsistency: seed "
                    "its random generators (and fix its thread count) inside the SUT, or raise eps above the "
                    "noise")

    def describe_transform(self, tau: Transform) -> str:
        return tau.describe("ref" if self.units is Units.REFERENCE else self.units.value)

    def failure_message(self, view: SceneView, tau: Any, result: MetricResult, record: dict, note: str) -> str:
        camera = record["camera"]
        lines = [
            (f"metamorphic relation violated: {self.metric!r} deviates {result.deviation:.4g} from its ideal "
             f"{self.metric.ideal:g}, more than eps={self.relation.eps:g}"),
            f"  scene:      {self.scene.name} (content {self.scene.content_hash[:12]})",
            f"  source:     view {view.name!r} ({view.split}), rendered at {camera['width']}x{camera['height']}",
        ]
        if _mutation_like(tau):
            lines.append(f"  follow-up:  the source render mutated by {tau.describe()}")
        else:
            lines.append(f"  transform:  {self.describe_transform(tau)}  ({note or 'minimal after shrinking'})")
            if any((tau.x, tau.y, tau.z)):
                scale = self.scene.length_scale(self.units)
                lines.append("              = " + ", ".join(
                    f"{n}={getattr(tau, n) * scale:+.4g}" for n in ("x", "y", "z") if getattr(tau, n)
                ) + " scene units" + self.metres(tau, scale))
        details = ", ".join(f"{k}={v}" for k, v in result.details.items())
        lines.append(f"  metric:     score {result.score:.4g}, deviation {result.deviation:.4g} > eps "
                     f"{self.relation.eps:g}" + (f" ({details})" if details else ""))
        s = self.stats
        lines.append(f"  search:     {_plural(s.examples, 'example')}, {s.inconsistencies} inconsistent, "
                     f"{s.n_rejected} rejected as invalid, {s.n_undefined} undefined, "
                     f"{_plural(s.shrink_examples, 'shrink step')}")
        if record.get("images"):
            images = record["images"]
            lines.append(f"  images:     source   {_shown_path(images['source'])}")
            lines.append(f"              follow   {_shown_path(images['follow'])}")
            lines.append(f"              (the renders the SUT saw: {Path(images['source_raw']).name}, "
                         f"{Path(images['follow_raw']).name})")
        elif self.images_error:
            lines.append(f"  images:     {self.images_error}")
        return "\n".join(lines)

    def metres(self, tau: Transform, scale: float) -> str:
        mpu = getattr(self.scene, "metres_per_unit", None)
        if not mpu:
            return ""
        parts = [f"{n}={getattr(tau, n) * scale * mpu:+.3g}" for n in ("x", "y", "z") if getattr(tau, n)]
        return " = " + ", ".join(parts) + " m"

    # -- replaying recorded examples --------------------------------------------------------------------

    def replay(self, records: list[Any]) -> list[dict[str, Any]]:
        """Evaluate each recorded example again, exactly: the recorded source pose, camera and follow-up."""
        out = []
        for rec in records:
            view = SceneView(index=-1, name=rec.view, camera=Camera.from_dict(rec.camera),
                             c2w=np.asarray(rec.source_c2w, dtype=np.float64).reshape(4, 4), split="replayed")
            out.append(self.evaluate(view, rec.follow_up(), camera=view.camera, units=Units(rec.units)).record)
        return out


def _check_output(output: Any, role: str, where: str, metric: Metric) -> None:
    """Reject outputs no metric can use: None and non-finite numbers (with the metric's expectation).

    An array that is *entirely* NaN goes to a metric whose ``nan_means_no_output`` is set (the vector
    metrics), which reads it as "no output" (undefined)."""
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


def _views_strategy(scene: Scene, relation: Relation) -> st.SearchStrategy[SceneView]:
    """Source views by name (so Hypothesis reports ``view='IMG_0042'``, not a pose matrix)."""
    if relation.interpolate and len(scene.views) >= 2:
        trajectory = list(scene.views)
        return st.builds(lambda i, k: interpolate_view(trajectory[i], trajectory[i + 1], k / 100),
                         st.integers(0, len(trajectory) - 2), st.integers(0, 100))
    names = [v.name for v in scene_views(scene, relation.views)]
    return st.sampled_from(names).map(scene.view)


def check_relation(scene: Scene, sut: Callable[[np.ndarray], Any], relation: Relation, *,
                   settings: RunSettings | None = None, cache: RenderCache | None = None,
                   test_id: str = "relation", replay: list[Any] | None = None,
                   on_start: Callable[[RelationStats], None] | None = None) -> RelationStats:
    """Search for a source view and transform where ``sut`` breaks ``relation`` on ``scene``.

    Returns the run's :class:`RelationStats` when the relation held on every valid example; raises
    :class:`RelationFailure` (with ``.stats``) naming the minimal failing transform, or saying that the
    SUT produced nothing to test (more than :data:`MAX_UNDEFINED` of the evaluated draws undefined);
    :class:`~pytest_n2r.errors.InvalidArgument` when almost every drawn follow-up view was invalid.
    ``replay``: recorded examples (:class:`~pytest_n2r.report.records.ExampleRecord`, e.g. a baseline's)
    evaluated exactly, before the search, into ``stats.replayed`` (their verdicts do not fail the run: a
    baseline comparison judges them). ``test_id`` names the run in reports and keys its Hypothesis database
    entries and seed; ``on_start`` receives the (still empty) stats before anything runs, so a caller keeps
    them even when the run raises.
    """
    __tracebackhide__ = True
    if not isinstance(scene, Scene):
        raise InvalidType(f"scene={scene!r} must be a pytest_n2r.Scene, not {type(scene).__name__}")
    if not callable(sut):
        raise InvalidType(f"sut={sut!r} must be a callable taking an H×W×3 uint8 RGB image, "
                          f"not {type(sut).__name__}")
    if not isinstance(relation, Relation):
        raise InvalidType(f"relation={relation!r} must be a Relation (build one with Relation.build)")
    settings = settings or RunSettings()
    scene.length_scale(transform_units(relation.transform))  # units='metres' on a scene without scale: say so now
    cache = cache if cache is not None else RenderCache(None)
    stats = RelationStats(test_id, scene.name, repr(relation.metric), relation.eps, scene.content_hash)
    if on_start is not None:
        on_start(stats)
    engine = _Engine(scene, sut, relation, settings, cache, stats)
    try:
        if replay is not None:
            stats.replayed = engine.replay(replay)
        _search(engine, scene, relation, settings, test_id)
    except RelationFailure as exc:
        stats.outcome, stats.message = "failed", str(exc)
        exc.stats = stats
        raise
    except (TimeLimitReached, NotDeterministic) as exc:  # escaped Hypothesis: the example ran once
        stats.outcome, stats.message = "error", str(exc)
        raise exc.error() from None
    except Flaky:  # a failure that passed on replay without the SUT changing its outputs: the scene's render
        stats.outcome = "error"
        stats.message = ("the relation failed on an example and passed when Hypothesis replayed it: something "
                         "is not deterministic. The system under test gave the same outputs twice on the first "
                         "failure, but may still vary from call to call; else the scene's renders (a custom Scene "
                         "with randomness?) or the metric vary")
        raise SUTNotDeterministic(stats.message) from None
    except BaseException as exc:
        stats.outcome, stats.message = "error", f"{type(exc).__name__}: {exc}"
        raise
    return stats


def replay_relation(scene: Scene, sut: Callable[[np.ndarray], Any], relation: Relation, examples: list[Any], *,
                    settings: RunSettings | None = None, cache: RenderCache | None = None,
                    test_id: str = "relation") -> RelationStats:
    """Evaluate exactly the recorded ``examples`` (e.g. a baseline's, see
    :func:`pytest_n2r.report.replay_candidates`) for ``sut`` on ``scene``, without a search: their records
    are ``stats.replayed``, in order. A verdict never raises; only the SUT's own errors do. Pair them with
    :func:`pytest_n2r.report.compare_paired`."""
    if not isinstance(scene, Scene):
        raise InvalidType(f"scene={scene!r} must be a pytest_n2r.Scene, not {type(scene).__name__}")
    if not isinstance(relation, Relation):
        raise InvalidType(f"relation={relation!r} must be a Relation (build one with Relation.build)")
    stats = RelationStats(test_id, scene.name, repr(relation.metric), relation.eps, scene.content_hash)
    engine = _Engine(scene, sut, relation, settings or RunSettings(), cache if cache is not None else RenderCache(None),
                     stats)
    stats.replayed = engine.replay(examples)
    return stats


def _search(engine: _Engine, scene: Scene, relation: Relation, settings: RunSettings, test_id: str) -> None:
    """The survey pass, then (after a failure) the shrink pass; raise the relation's verdict."""
    __tracebackhide__ = True
    stats = engine.stats

    def example(view: SceneView, tau: Any) -> None:
        __tracebackhide__ = True
        engine.example(view, tau)

    # key this run's database entries and (with derandomize) its seed to the test, scene and relation
    example._hypothesis_internal_add_digest = f"{test_id}|{scene.name}|{relation.describe()}".encode()
    options: dict[str, Any] = {
        "max_examples": relation.examples or settings.examples, "deadline": None,
        "derandomize": settings.derandomize,
        "suppress_health_check": [HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large],
        # no "explain" phase: it re-runs variations of the failure (renders) to annotate source lines
        "phases": [Phase.explicit, Phase.reuse, Phase.generate, Phase.target, Phase.shrink],
    }
    database = None if settings.derandomize else (
        hsettings().database if settings.database == "default" else settings.database)
    seed = None if settings.derandomize else random.getrandbits(64)  # both passes draw the same examples

    def run(db: Any) -> None:
        test = given(view=_views_strategy(scene, relation), tau=relation.transform)(example)
        if seed is not None:
            test = hypothesis_seed(seed)(test)
        hsettings(**options, database=db)(test)()

    try:  # the survey: records every draw, never fails (and leaves the example database as it was)
        with _without_local_constants():
            run(None if database is None else ReadOnlyDatabase(database))
    except Unsatisfiable:
        pass
    drawn = stats.examples + stats.n_rejected + stats.n_undefined
    evaluated = stats.examples + stats.n_undefined
    if stats.n_undefined and stats.n_undefined / evaluated > MAX_UNDEFINED:
        raise RelationFailure(_nothing_to_test(stats, relation), stats)
    if engine.gave_up == "invalid" or not drawn or stats.n_rejected / drawn > relation.validity.max_rejected:
        raise InvalidArgument(_too_many_invalid(stats, relation))
    if not stats.inconsistencies:
        return
    engine.shrinking = True
    try:
        with _without_local_constants():
            run(database)
    except Unsatisfiable:
        pass
    # the shrink pass did not reproduce the survey's failure (a SUT that is not deterministic): report the
    # survey's worst failing example as it was drawn
    worst = stats.worst
    view = SceneView(index=-1, name=worst["view"], camera=Camera.from_dict(worst["camera"]),
                     c2w=np.asarray(worst["source_c2w"]).reshape(4, 4), split="drawn")
    from .report.records import ExampleRecord

    tau = ExampleRecord.from_dict(worst).follow_up()
    engine.fail(view, tau, engine.evaluate(view, tau, camera=view.camera),
                note="not shrunk: the shrink pass did not reproduce it; is the SUT deterministic?")


@contextmanager
def _without_local_constants() -> Iterator[None]:
    """Hypothesis mixes numbers it finds in the source of the loaded local modules into its draws, so which
    modules happen to be imported changed the examples of a derandomized search (a rerun in one process, a
    pytest-xdist worker, a run that loads the report modules earlier). The engine's draws (views,
    transforms) gain nothing from them, so they are off while it searches. This patches Hypothesis's
    internal ``providers`` module; if that moves, nothing is patched."""
    try:
        from hypothesis.internal.conjecture import providers

        empty, original, cache = providers.Constants(), providers._get_local_constants, providers.CONSTANTS_CACHE
        cache.cache.clear()
    except (ImportError, AttributeError):
        yield
        return
    providers._get_local_constants = lambda: empty
    try:
        yield
    finally:
        providers._get_local_constants = original
        cache.cache.clear()


def _shown_path(path: str | os.PathLike) -> str:
    """``path`` relative to the current directory when it lies inside it (shorter, and what a reader can
    open from where they ran pytest), else as it is."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _nothing_to_test(stats: RelationStats, relation: Relation) -> str:
    evaluated = stats.examples + stats.n_undefined
    reasons = "; ".join(f"{n}x {r}" for r, n in stats.undefined.most_common(3))
    return (
        f"the SUT produced nothing to test: {relation.metric!r} was undefined on {stats.n_undefined} of "
        f"{evaluated} evaluated draws ({stats.n_undefined / evaluated:.0%} > {MAX_UNDEFINED:.0%}) on scene "
        f"{stats.scene!r}: {reasons}. A SUT that returns nothing (no keypoints, an empty or all-NaN output) "
        "never passes a relation"
    )


def _too_many_invalid(stats: RelationStats, relation: Relation) -> str:
    drawn = stats.examples + stats.n_rejected + stats.n_undefined
    share = stats.n_rejected / drawn if drawn else 1.0
    reasons = ", ".join(f"{r}: {n}" for r, n in stats.rejected.most_common()) or "no valid example"
    return (
        f"{relation.transform!r} leaves what the scene {stats.scene!r} can render faithfully in {share:.0%} of "
        f"{drawn} draws ({reasons}); narrow the bounds (or use look_at=True) so most follow-up views stay "
        "in the captured region"
    )
