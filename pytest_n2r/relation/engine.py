"""The relation engine: one relation on one scene with one SUT, evaluated one drawn (or replayed) example
at a time -- render the source and its follow-up, judge the follow-up's validity, run the SUT on both,
compare with the metric -- each into an :class:`~pytest_n2r.relation.record.ExampleRecord` of the run's
:class:`~pytest_n2r.relation.record.RelationRecord`.
:mod:`pytest_n2r.relation.search` drives it with Hypothesis.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from hypothesis import assume, target

from ..errors import InvalidArgument, InvalidType, MetricArgumentError, MetricUndefined, SUTOutputError
from ..geometry import Camera
from ..metrics.base import MetricResult
from ..render.view import RenderedView
from ..scene.base import Scene, SceneView, normalize_outputs
from ..scene.first_render import rendered as kind_rendered
from ..scene.first_render import renderer_kind
from ..scene.render_cache import RenderCache
from ..strategies.follow_up import FollowUp
from ..strategies.pose_change import as_follow_up
from .artifacts import artifact_dir, save_pair
from .determinism import check_deterministic, same_output
from .failure import MAX_UNDEFINED, SAME_PIXELS, RelationFailure, failure_message, how_to_reproduce
from .kept_results import kept_result, repainted_key
from .outputs import SUTError, check_output, sut_image
from .record import ExampleRecord, RelationRecord
from .settings import RunSettings
from .spec import Relation
from .sut_outputs import MISSING, SUTOutputs
from .timeout import time_limit
from .validity import Verdict, too_many_invalid_so_far

__all__ = ["Engine", "Evaluation", "recorded_view", "same_pixels"]

def forced_seed() -> object:
    """pytest's ``--hypothesis-seed`` (``None`` without it): Hypothesis keeps no example database under it."""
    from hypothesis import core

    return getattr(core, "global_force_seed", None)


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


@dataclass
class Evaluation:
    """One drawn example evaluated: its record and what a failure report needs."""

    record: ExampleRecord
    where: str = ""
    result: MetricResult | None = None
    source: RenderedView | None = None
    follow: RenderedView | None = None
    outputs: tuple[Any, Any] = (None, None)

    def images(self) -> tuple[np.ndarray, np.ndarray]:  # of an example the SUT ran on: not rejected, not undefined
        assert self.source is not None and self.follow is not None, "the SUT did not run on this example"
        return sut_image(self.source, "source"), sut_image(self.follow, "follow-up")


class Engine:
    """One relation on one scene with one SUT: evaluates drawn (or replayed) examples.

    The search runs in two passes that draw the same examples (same seed): the *survey* records every
    draw and never raises, so a relation's records cover all its examples, not just those up to the first
    failure; only when the survey saw a failure does the *shrink* pass run, raising at the first failure so
    Hypothesis shrinks it to the smallest transform."""

    def __init__(self, scene: Scene, sut: Callable[[np.ndarray], Any], relation: Relation,
                 settings: RunSettings, cache: RenderCache, run_record: RelationRecord,
                 sut_outputs: SUTOutputs | None = None):
        self.scene, self.sut, self.relation, self.settings = scene, sut, relation, settings
        self.cache, self.run_record = cache, run_record
        #: The SUT's outputs on renders, by render key: the session's (shared with its other relations) or
        #: this run's own (so the SUT still runs once per source view).
        self.sut_outputs = sut_outputs if sut_outputs is not None else SUTOutputs()
        #: Whether this run has called its SUT again on an image whose output another run left
        #: (:meth:`sut_on_render`): a SUT object reconfigured between tests keeps its identity
        self.sharing_checked = sut_outputs is None
        self.own_outputs: set[str] = set()  # the render keys this run kept the SUT's output of
        self.metric = relation.metric
        self.size = relation.size or settings.size
        needs = tuple(getattr(self.metric, "needs", ()) or ())
        self.outputs = normalize_outputs(("rgb", *needs, *(("opacity",) if relation.validity.outputs else ())))
        self.follow_outputs = normalize_outputs(("rgb", *needs, *relation.validity.outputs))
        to_dict = getattr(getattr(scene, "settings", None), "to_dict", None)
        self.render_settings = to_dict() if callable(to_dict) else {}
        self.shrinking = False  # False: the survey pass; True: the shrink pass (start_shrink_pass)
        self.failed = False
        self.gave_up = ""  # why the survey stopped drawing early ("" while it goes on)
        self.drawn: set[tuple[str, bytes, str]] = set()  # this pass's examples so far (source view, follow-up)
        self.failing: set[tuple[str, bytes, str]] = set()  # the examples found inconsistent, in either pass
        self.raised: set[tuple[str, bytes, str]] = set()  # the examples on which the SUT raised, in either pass
        self.images_error: str | None = None

    # -- pieces -----------------------------------------------------------------------------------------

    def camera_for(self, view: SceneView) -> Camera:
        return view.camera if self.size is None else self.size.apply(view.camera)

    def render(self, c2w: np.ndarray, camera: Any, view: SceneView, outputs: tuple[str, ...],
               role: str) -> tuple[RenderedView, str]:
        """The render (from the cache where possible) and its render key."""
        start = time.perf_counter()
        renders = self.cache.stats.renders
        # a process's first render of a renderer kind compiles its kernels or waits for another process that
        # compiles them (seconds, minutes on a loaded machine): no hang, so the limit holds from the next one
        limit = self.settings.timeout if kind_rendered(renderer_kind(self.scene)) else None
        with time_limit(limit, f"rendering the {role} view of {view.name!r}", escape=True):
            rendered = self.cache.render_keyed(self.scene, c2w, camera, outputs)
        self.run_record.timings["render"] += time.perf_counter() - start
        self.run_record.renders += self.cache.stats.renders - renders
        return rendered

    def run_sut(self, rgb: np.ndarray, role: str, where: str) -> Any:
        __tracebackhide__ = True  # a failure shows the SUT's own traceback and the message, not the engine's
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
            self.run_record.timings["sut"] += time.perf_counter() - start
            self.run_record.sut_calls += 1
        check_output(output, role, where, self.metric)
        return output

    def sut_on_render(self, rendered: RenderedView, key: str | None, role: str, where: str) -> Any:
        """The SUT's output on a render: kept from an earlier call on the render ``key`` (by this relation or,
        with a session's :class:`SUTOutputs`, another one running the same SUT object), else a new call.
        ``key=None``: an image that is not a render (a mutation's)."""
        __tracebackhide__ = True
        if key is not None:
            output = self.sut_outputs.get(self.sut, key)
            if output is not MISSING and not self.sharing_checked and key not in self.own_outputs:
                # the first output another test left: a SUT object reconfigured since (a fixture's detector given
                # another threshold, a module's function whose global a test patched) must not be judged by it
                self.sharing_checked = True
                fresh = self.run_sut(sut_image(rendered, role), role, where)
                if not same_output(fresh, output):
                    self.sut_outputs.forget(self.sut)
                output = fresh
            elif output is not MISSING:
                self.run_record.sut_shared += 1
                check_output(output, role, where, self.metric)
                return output
            else:
                output = self.run_sut(sut_image(rendered, role), role, where)
        else:
            output = self.run_sut(sut_image(rendered, role), role, where)
        if key is not None:
            self.sut_outputs.put(self.sut, key, output)
            self.own_outputs.add(key)
        return output

    def compute(self, out_source: Any, out_follow: Any, source: RenderedView, follow: RenderedView,
                where: str) -> MetricResult:
        start = time.perf_counter()
        try:
            result = self.metric.compute(out_source, out_follow, source, follow)
        except MetricUndefined as exc:  # the pair tests nothing (e.g. no keypoint in the common region)
            return MetricResult.undefined(self.metric.name, str(exc))
        except MetricArgumentError as exc:  # the test's mistake: said as such, not blamed on the SUT
            raise MetricArgumentError(f"{self.metric!r} ({where}): {exc}") from None
        except (InvalidType, InvalidArgument) as exc:
            if isinstance(exc, SUTOutputError):
                raise
            raise SUTOutputError(f"{self.metric!r} cannot use the SUT's output ({where}): {exc}") from exc
        finally:
            self.run_record.timings["metric"] += time.perf_counter() - start
        if not isinstance(result, MetricResult):
            raise InvalidType(f"{self.metric!r}.compute returned {type(result).__name__}, not a MetricResult")
        if getattr(result, "valid", True) and not math.isfinite(result.deviation):
            raise SUTOutputError(
                f"{self.metric!r} gave deviation {result.deviation} ({where}); the SUT's output probably "
                "contains NaN or Inf"
            )
        if getattr(result, "valid", True) and result.deviation < 0:  # a metric's own mistake, not the SUT's
            raise InvalidType(f"{self.metric!r} gave deviation {result.deviation:g} ({where}); expected a deviation "
                              "from the ideal >= 0 (0: ideal, larger: worse), e.g. abs(score - ideal)")
        return result

    def compute_on_renders(self, out_source: Any, out_follow: Any, source: RenderedView, follow: RenderedView,
                           source_key: str, follow_key: str | None, where: str) -> MetricResult:
        """:meth:`compute`, or its result kept from an earlier evaluation of the same SUT and metric objects on
        the same two renders (a replayed example), or from an earlier session's evaluation of the same metric on
        the same two outputs and renders, in the render cache (a warm run; :mod:`.kept_results`);
        ``follow_key=None`` (an image that is no render, nor a render with other pixels): always computed."""
        if follow_key is None:
            return self.compute(out_source, out_follow, source, follow, where)
        result = self.sut_outputs.result(self.sut, self.metric, source_key, follow_key)
        if result is MISSING:
            before, start = self.run_record.timings["metric"], time.perf_counter()
            result = kept_result(self.cache, self.metric, source_key, follow_key, out_source, out_follow,
                                 lambda: self.compute(out_source, out_follow, source, follow, where))
            self.run_record.timings["metric"] = before + time.perf_counter() - start  # the look-up's time too
            self.sut_outputs.put_result(self.sut, self.metric, source_key, follow_key, result)
        return result

    def validity(self, follow: RenderedView, source: RenderedView, source_key: str,
                 follow_key: str | None) -> Verdict:
        """The relation's validity verdict on a follow-up render, or the one kept from an earlier check with the
        same thresholds of the same two renders against the same training cameras: in this session (a
        replayed example: a regression gate's) or in the render cache, beside the renders (a warm run);
        ``follow_key=None`` (not a render): always checked. The scene is in the keys (its content hash)."""
        validity = self.relation.validity
        if follow_key is None:
            return validity.check(follow, self.scene, source)
        verdict = self.sut_outputs.verdict(validity, source_key, follow_key)
        if verdict is MISSING:
            stored_key = validity.verdict_key(self.scene, source_key, follow_key)  # None: a subclass's, not kept
            stored = self.cache.decision(stored_key) if stored_key is not None else None
            try:
                verdict = Verdict.from_dict(stored) if stored is not None else None
            except (KeyError, TypeError):  # another shape of decision under the key: checked again
                verdict = None
            if verdict is None:
                verdict = validity.check(follow, self.scene, source)
                if stored_key is not None:
                    self.cache.put_decision(stored_key, verdict.to_dict())
            self.sut_outputs.put_verdict(validity, source_key, follow_key, verdict)
        return verdict

    # -- one example ------------------------------------------------------------------------------------

    def evaluate(self, view: SceneView, tau: FollowUp, camera: Any = None) -> Evaluation:
        """Render, check validity, run the SUT and the metric on one example; never raises on a verdict.

        ``camera`` (a replayed example's recorded one) overrides the run's render size."""
        __tracebackhide__ = True  # a SUT's error shows its own traceback (--full-trace shows the engine's)
        camera = camera if camera is not None else self.camera_for(view)
        tau.check_scene(self.scene)  # e.g. units='metres' on a scene without scale: said before any render
        where = f"scene {self.scene.name!r}, source view {view.name!r}, {tau.describe()}"
        record = ExampleRecord(
            scene=self.scene.name, scene_hash=self.scene.content_hash, view=view.name,
            source_c2w=np.asarray(view.c2w, dtype=np.float64).ravel().tolist(), camera=camera.to_dict(),
            settings=self.render_settings, **tau.record_fields(), score=math.nan, deviation=math.nan,
            passed=False,
        )
        source, source_key = self.render(view.c2w, camera, view, self.outputs, "source")
        rendered: list[tuple[RenderedView, str]] = []

        def render_follow(c2w: np.ndarray) -> RenderedView:
            rendered.append(self.render(c2w, camera, view, self.follow_outputs, "follow-up"))
            return rendered[-1][0]

        follow = tau.follow_view(source, self.scene, render_follow)
        # the SUT's output is kept by render: the follow-up is one when it is what the render returned, unchanged
        follow_key = rendered[-1][1] if rendered and follow is rendered[-1][0] else None
        if same_pixels(sut_image(follow, "follow-up"), sut_image(source, "source")):
            record.status, record.reason = "undefined", SAME_PIXELS  # a deterministic SUT cannot fail on it
            return Evaluation(record, where)
        if tau.moves_camera:  # a new render: is it within what the scene renders faithfully?
            start = time.perf_counter()
            verdict = self.validity(follow, source, source_key, follow_key)
            self.run_record.timings["validity"] += time.perf_counter() - start
            if not verdict.valid:
                record.status, record.reason = "rejected", verdict.reason
                return Evaluation(record, where)
        out_source = self.sut_on_render(source, source_key, "source", where)
        out_follow = self.sut_on_render(follow, follow_key, "follow-up", where)
        # a mutation's follow-up is its source render with other pixels: its metric result is kept under both
        result = self.compute_on_renders(out_source, out_follow, source, follow, source_key,
                                         follow_key or repainted_key(source, source_key, follow), where)
        if not getattr(result, "valid", True):
            record.status, record.reason = "undefined", str(result.details.get("reason", "metric undefined"))
        else:
            record.score, record.deviation = float(result.score), float(result.deviation)
            record.passed = record.deviation <= self.relation.eps
        return Evaluation(record, where, result, source, follow, (out_source, out_follow))

    def count(self, record: ExampleRecord) -> None:
        """Record a survey example and stop drawing once the relation's end is known: so many undefined draws that
        they are more than :data:`MAX_UNDEFINED` of the evaluated ones even if every example asked for is valid, or
        at least 40 invalid ones whose share is above ``max_rejected`` with 99 % confidence (Clopper-Pearson).

        Stopping on the running shares instead ended relations that would have passed: more than half undefined
        at some draw when 40-45 % were, above 90 % invalid at some draw when 80-85 % were
        (``tests/relation/test_engine.py -k gives_up`` measures both rules).
        """
        run = self.run_record
        run.examples.append(record)
        if too_many_invalid_so_far(run.rejected, len(run.examples), self.relation.validity.max_rejected):
            self.gave_up = "invalid"  # check_relation raises once Hypothesis stops
        if run.undefined / (run.asked + run.undefined) > MAX_UNDEFINED:  # asked: the most valid examples there can be
            self.gave_up = "undefined"

    def start_shrink_pass(self) -> None:
        """Evaluate the next examples as the shrink pass: a failure raises (Hypothesis shrinks it)."""
        self.shrinking, self.drawn = True, set()

    def example(self, view: SceneView, tau: Any) -> None:
        """The body of one Hypothesis example (survey or shrink pass)."""
        __tracebackhide__ = True
        tau = as_follow_up(tau)
        drawn = (view.name, np.asarray(view.c2w, np.float64).tobytes(),
                 json.dumps(tau.record_fields(), sort_keys=True, default=str))
        if self.gave_up and drawn not in self.raised:  # reject the rest of the draws without rendering them
            assume(False)
        if drawn in self.drawn and drawn not in self.raised and not (self.shrinking and drawn in self.failing):
            # the same example again tests nothing new: not counted, Hypothesis draws another. The shrink pass
            # rejects repeats as the survey did, so that with the survey's seed it draws the survey's examples up
            # to the first failure (Hypothesis's draws follow what each example did). An example the SUT raised on
            # is evaluated again whenever it comes back: Hypothesis replays its error last, and a repeat that
            # passed in between (an intermittent SUT) must not turn that replay into an "unreliable assumption"
            assume(False)
        try:
            evaluation = self.evaluate(view, tau)
        except Exception:
            self.raised.add(drawn)
            raise
        record = evaluation.record
        self.drawn.add(drawn)
        if record.valid and not record.passed:
            self.failing.add(drawn)
        if not self.shrinking:
            if record.valid and not record.passed and not self.run_record.inconsistencies:
                check_deterministic(self.run_sut, *evaluation.images(), *evaluation.outputs, evaluation.where)
            self.count(record)
        elif self.failed:
            self.run_record.shrink_examples += 1
        if not record.valid:
            assume(False)  # not a test: Hypothesis draws another
        if self.relation.search == "targeted":
            target(record.deviation, label="deviation")
        if record.passed or not self.shrinking:
            return
        self.failed = True
        if not _is_final_example():
            raise RelationFailure("inconsistent (shrinking)")
        self.fail(view, tau, evaluation)

    def fail(self, view: SceneView, tau: FollowUp, evaluation: Evaluation, note: str = "") -> None:
        """Save the failure pictures and raise the :class:`RelationFailure` of ``evaluation``."""
        __tracebackhide__ = True
        record, run, result = replace(evaluation.record), self.run_record, evaluation.result
        assert result is not None, "a failure is an example whose metric compared the SUT's outputs"
        if self.settings.artifacts is not None:
            try:
                record.images = save_pair(artifact_dir(self.settings.artifacts, run.nodeid),
                                             *evaluation.images(), *evaluation.outputs)
            except OSError as exc:  # a full disk or a read-only folder must not hide the failure itself
                self.images_error = f"not saved ({exc.strerror or exc}: {exc.filename or self.settings.artifacts})"
        run.minimal = record
        message = failure_message(self.scene, self.relation, run, view, tau, result, record, note=note,
                                  images_error=self.images_error,
                                  reproduce=how_to_reproduce(self.settings.derandomize, self.settings.database,
                                                            forced_seed()))
        raise RelationFailure(message, run)

    def replay(self, records: list[ExampleRecord]) -> list[ExampleRecord]:
        """Evaluate each recorded example again, exactly: the recorded source pose, camera and follow-up."""
        out = []
        for rec in records:
            view = recorded_view(rec, "replayed")
            out.append(self.evaluate(view, rec.follow_up(), camera=view.camera).record)
        return out


def same_pixels(image: np.ndarray, other: np.ndarray) -> bool:
    """Whether two images are the same array or equal byte for byte (shape, dtype and every value).

    >>> a = np.zeros((2, 3, 3), np.uint8)
    >>> same_pixels(a, a.copy()), same_pixels(a, a.astype(np.float32)), same_pixels(a, a[:1])
    (True, False, False)
    """
    return image is other or (image.shape == other.shape and image.dtype == other.dtype
                              and bool(np.array_equal(image, other)))


def recorded_view(record: ExampleRecord, split: str) -> SceneView:
    """The source view of a recorded example, exactly as recorded (pose and camera, render size included)."""
    return SceneView(index=-1, name=record.view, camera=Camera.from_dict(record.camera),
                     c2w=np.asarray(record.source_c2w, dtype=np.float64).reshape(4, 4), split=split)

