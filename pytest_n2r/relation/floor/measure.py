"""The field floor of one SUT and metric on one scene at one render size: the mean deviation, over the
held-out views whose metric is defined, between the SUT's output on each view's reference image and on the
field's render at the same pose (:func:`measure_floor`), beside the same measured on the capture's nearest other
photo brought to each pose (:mod:`~pytest_n2r.relation.floor.nearby`: what an image taken nearby gives), kept in
memory and on disk by a :class:`FloorStore`. See :mod:`pytest_n2r.relation.floor` for what it means.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ... import __version__
from ...data.atomic import atomic_write_text
from ...geometry import Camera
from ...metrics.base import Metric
from ...render.size import RenderSize
from ...render.view import RenderedView
from ...scene.base import Scene, SceneView, normalize_outputs
from ...scene.cache_files import touch
from ...scene.render_cache import RenderCache, source_digest
from ..kept_results import output_digest, result_key
from ..outputs import sut_image
from .nearby import nearby_image
from .reference import ShiftSample, exact_twin, floor_views, reference_image, reference_kind, shift_sample

__all__ = ["FLOOR_VERSION", "FieldFloor", "FloorStore", "json_number", "measure_floor", "sut_name"]

#: Bumped when the measurement changes, so cached floors of an older measurement are not reused
#: (2: the nearest other photo's samples beside the render's; 3: a non-finite deviation is no sample; 4: a 'WxH'
#: size keeps each view's aspect, where it stretched views of another; 5: keyed by the SUT's outputs on every
#: reference image and by the package's source, not by its output on the first image alone; 6: by its outputs on the
#: field renders and nearby images too, and kept only for a metric whose class declares its own ``result_version``).
FLOOR_VERSION = 6


@dataclass(frozen=True)
class FieldFloor:
    """The reality-to-field shift of one SUT and metric on one scene at one render size.

    ``reference`` is ``"photo"``, ``"exact"`` or ``"none"`` (then ``reason`` says why there is no floor);
    ``samples`` holds one :class:`ShiftSample` per held-out view. :attr:`value` is the mean deviation of
    the defined samples (NaN when none is defined). ``nearby`` holds, per held-out view, the same SUT and metric
    between the reference image and the nearest other fitted view's reference image brought to the pose
    (how far those views were: ``nearby_degrees``, the median angle between optical axes, and
    ``nearby_distance``, the median distance between centres in reference lengths); empty when the scene has no
    other fitted view with a reference image. :attr:`nearby_value` is their mean deviation."""

    scene: str
    sut: str
    metric: str
    size: str
    reference: str
    samples: tuple[ShiftSample, ...] = ()
    reason: str = ""
    key: str = ""
    nearby: tuple[ShiftSample, ...] = ()
    nearby_degrees: float = math.nan
    nearby_distance: float = math.nan

    @property
    def deviations(self) -> list[float]:
        return [s.deviation for s in self.samples if s.valid]

    @property
    def nearby_value(self) -> float:
        """The mean deviation of the defined :attr:`nearby` samples (NaN when none is defined)."""
        defined = [s.deviation for s in self.nearby if s.valid]
        return float(np.mean(defined)) if defined else math.nan

    @property
    def n(self) -> int:
        """Held-out views whose metric is defined."""
        return len(self.deviations)

    @property
    def available(self) -> bool:
        return self.n > 0

    @property
    def value(self) -> float:
        """The floor: mean deviation over the defined held-out views (NaN when there is none)."""
        return float(np.mean(self.deviations)) if self.deviations else math.nan

    @property
    def max(self) -> float:
        return float(np.max(self.deviations)) if self.deviations else math.nan

    @property
    def why_unavailable(self) -> str:
        if self.available:
            return ""
        if self.reason:
            return self.reason
        reasons = sorted({s.reason for s in self.samples if not s.valid})
        return (f"the metric is undefined on all {len(self.samples)} held-out views"
                + (f" ({'; '.join(reasons)})" if reasons else ""))

    def above(self, eps: float) -> bool:
        """True when ``eps`` is below the floor: the relation then tests the scene field, not the SUT."""
        return self.available and eps < self.value

    def describe(self, eps: float | None = None) -> str:
        """One line: ``field floor 0.31 (photo vs render, mean of 7 held-out views, max 0.45)``, with a
        warning when ``eps`` is below it."""
        if not self.available:
            return f"field floor n/a: {self.why_unavailable}"
        against = "photo" if self.reference == "photo" else "exact render"
        undefined = len(self.samples) - self.n
        nearby = (f"; the nearest other {'photo' if self.reference == 'photo' else 'view'} brought to each pose "
                  f"({self.nearby_degrees:.1f}° and {self.nearby_distance:.2g} reference lengths away): "
                  f"{self.nearby_value:.3g}"
                  if math.isfinite(self.nearby_value) else "")
        text = (f"field floor {self.value:.3g} ({against} vs field render at the same pose, mean of "
                f"{self.n} held-out view{'s' if self.n != 1 else ''}, max {self.max:.3g}"
                + (f", {undefined} undefined" if undefined else "") + nearby + ")")
        if eps is not None and self.above(eps):
            text += (f"; WARNING: eps {eps:g} is below the field floor: this relation tests the scene field, "
                     "not the SUT")
        elif eps is not None and (over := sum(d > eps for d in self.deviations)):
            # a relation fails on its worst example: a view whose floor alone exceeds eps may decide it
            text += (f"; note: eps {eps:g} is below the floor on {over} of {self.n} held-out views (max "
                     f"{self.max:.3g}): there the field alone exceeds it")
        return text

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as ``None``), with the summary values for readers of reports."""
        d = asdict(self)
        for name in ("samples", "nearby"):
            d[name] = [{**s, "score": json_number(s["score"]), "deviation": json_number(s["deviation"])}
                       for s in d[name]]
        d.update(value=json_number(self.value), max=json_number(self.max), n=self.n,
                 nearby_value=json_number(self.nearby_value), nearby_degrees=json_number(self.nearby_degrees),
                 nearby_distance=json_number(self.nearby_distance))
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FieldFloor:
        def samples(name: str) -> tuple[ShiftSample, ...]:
            return tuple(ShiftSample(s["view"], _num(s["score"]), _num(s["deviation"]), bool(s["valid"]),
                                     s.get("reason", "")) for s in d.get(name, ()))

        return cls(d["scene"], d["sut"], d["metric"], d["size"], d["reference"], samples("samples"),
                   d.get("reason", ""), d.get("key", ""), samples("nearby"), _num(d.get("nearby_degrees")),
                   _num(d.get("nearby_distance")))


def json_number(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _num(x: float | None) -> float:
    return math.nan if x is None else float(x)


class FloorStore:
    """Measured floors, in memory and (with a ``directory``) on disk as JSON, one file per key (a render cache's
    ``floors/``: trimmed with its renders, least recently used first, which a read refreshes)."""

    def __init__(self, directory: str | os.PathLike | None = None):
        self.directory = Path(directory) if directory is not None else None
        self._memory: dict[str, FieldFloor] = {}

    def get(self, key: str) -> FieldFloor | None:
        floor = self._memory.get(key)
        if floor is None and self.directory is not None:
            path = self.directory / f"{key}.json"
            try:
                floor = FieldFloor.from_dict(json.loads(path.read_text()))
            # absent, torn by a crash, or not a floor (nested too deep, another shape): measure again
            except (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError):
                return None
            touch(path)  # recently used: trimmed last
            self._memory[key] = floor
        return floor

    def put(self, floor: FieldFloor) -> None:
        self._memory[floor.key] = floor
        if self.directory is not None:
            try:  # kept only to save a later session the measurement: a clear or a full disk loses just that
                atomic_write_text(self.directory / f"{floor.key}.json", json.dumps(floor.to_dict(), indent=1) + "\n")
            except OSError:
                pass


def sut_name(sut: Callable[..., Any]) -> str:
    """``module:qualname`` of a SUT callable (its class's for a callable object)."""
    target = sut if hasattr(sut, "__qualname__") else type(sut)
    return f"{getattr(target, '__module__', '?')}:{getattr(target, '__qualname__', type(sut).__name__)}"


def measure_floor(scene: Scene, sut: Callable[[np.ndarray], Any], metric: Metric, *,
                  size: RenderSize | None = None, cache: RenderCache | None = None,
                  store: FloorStore | None = None, name: str | None = None,
                  max_views: int | None = 12, nearby: bool | None = None) -> FieldFloor:
    """The field floor of ``sut`` (an H×W×3 uint8 RGB image → its output) under ``metric`` on ``scene``,
    rendered at ``size`` (``None``: each view's camera) on at most ``max_views`` held-out views; with ``nearby``
    the same on the nearest other photo brought to each pose beside it (``None``: where the reference is a
    photo; on a fitted demo scene the relation's replay on exact renders says more, and costs no extra render).

    Renders go through ``cache`` (default: none); ``store`` keeps measured floors keyed by the scene's
    content hash, the exact twin's, the SUT (``name``, default :func:`sut_name`, and an exact digest of every output
    the floor is computed from: on each reference image, each field render and each nearby image, so an edited SUT
    whose output changes on any of them is measured again), the metric (as a kept metric result is keyed,
    :func:`~pytest_n2r.relation.kept_results.result_key`: its class, ``repr`` and ``result_version``; a metric of
    pytest-n2r's own by its class, its code named by the source digest), the size,
    the views, whether ``nearby``, :data:`FLOOR_VERSION`, the package's version and source
    (:func:`~pytest_n2r.scene.render_cache.source_digest`) and numpy's version. Taking a kept floor therefore costs
    every SUT call measuring it makes (two per held-out view, three with ``nearby``; the renders and reference
    images come from ``cache`` when it holds them) and saves the metric's. A floor is neither kept nor reused when
    the metric is a user's whose class declares no ``result_version`` of its own (its arithmetic no version names:
    an edited ``compute`` is measured again), nor when an output has no exact digest
    (:func:`~pytest_n2r.relation.kept_results.output_digest`: an object that is not numbers, strings, arrays,
    tensors, ``cv2.KeyPoint`` objects, lists, tuples or string-keyed dicts of them).
    """
    name = name or sut_name(sut)
    size_text = "view size" if size is None else str(size)
    kind, reason = reference_kind(scene)
    if kind == "none":
        return FieldFloor(scene.name, name, repr(metric), size_text, kind, reason=reason)
    nearby = kind == "photo" if nearby is None else bool(nearby)
    views = floor_views(scene, max_views)
    render_cache = cache if cache is not None else RenderCache(None)

    def camera_of(view: SceneView) -> Camera:
        return view.camera if size is None else size.apply(view.camera)

    needs = ("depth", "opacity") if nearby else (getattr(metric, "needs", ()) or ())
    outputs = normalize_outputs(("rgb", *needs))

    def render(s: Scene, c2w: np.ndarray, camera: Camera) -> RenderedView:
        # with nearby, depth and opacity too: the nearest other photo is brought to the pose through them
        return render_cache.render(s, c2w, camera, outputs if s is scene else ("rgb",))

    references = [reference_image(scene, v, camera_of(v), kind, render) for v in views]
    renders = [render(scene, v.c2w, camera_of(v)) for v in views]
    nears = [nearby_image(scene, v, r, size, kind, render) if nearby else None for v, r in zip(views, renders)]
    # every SUT output the floor is computed from, before the store is asked: an edited SUT whose output changes
    # only on the (blurrier) field renders or nearby images is measured again, not given the old SUT's floor
    outs_real = [sut(image) for image in references]
    outs_field = [sut(sut_image(r, "field")) for r in renders]
    outs_near = [None if near is None else sut(near.image) for near in nears]
    twin = exact_twin(scene) if kind == "exact" else None
    digests = {"reference": [output_digest(out) for out in outs_real],
               "field": [output_digest(out) for out in outs_field],
               "nearby": [output_digest(out) if near is not None else "-" for out, near in zip(outs_near, nears)]}
    # the metric as its kept results are keyed (class, repr, its class's own result_version), or, for a metric of
    # pytest-n2r's own (cosine, L2, class invariance, SSIM), by its class and the package's source digest below; a
    # user's metric whose class declares no result_version is never kept: an edited compute would get its old floor
    cls = type(metric)
    ours = cls.__module__.startswith("pytest_n2r.")
    metric_key = result_key(metric, "field floor", "field floor", None, None) or (
        f"{cls.__module__}.{cls.__qualname__}" if ours else None)
    spec = {"floor": FLOOR_VERSION, "pytest_n2r": __version__, "source": source_digest(), "numpy": np.__version__,
            "scene": scene.content_hash, "twin": twin.content_hash if twin is not None else None, "sut": name,
            "outputs": digests, "metric": repr(metric), "metric_key": metric_key,
            "result_version": type(metric).result_version, "size": size_text, "views": [v.name for v in views],
            "reference": kind, "nearby": nearby}
    key = hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:32]
    if metric_key is None or any(None in of_outputs for of_outputs in digests.values()):
        store, key = None, ""  # an unversioned metric or an output no digest names exactly: neither kept nor reused
    if store is not None and (known := store.get(key)) is not None:
        return known
    samples, nearby_samples, gaps = [], [], []
    for view, image, rendered, out_real, out_field, near, out_near in zip(views, references, renders, outs_real,
                                                                           outs_field, nears, outs_near):
        real = RenderedView(rendered.camera, rendered.c2w, rgb=image, depth=rendered.depth, opacity=rendered.opacity)
        samples.append(shift_sample(metric, out_real, out_field, real, rendered, view.name))
        if near is not None:
            nearby_samples.append(shift_sample(metric, out_real, out_near, real,
                                               replace(rendered, rgb=near.image), view.name))
            gaps.append((near.degrees, near.distance))
    degrees, distance = np.median(gaps, axis=0) if gaps else (math.nan, math.nan)
    floor = FieldFloor(scene.name, name, repr(metric), size_text, kind, tuple(samples), key=key,
                       nearby=tuple(nearby_samples), nearby_degrees=float(degrees), nearby_distance=float(distance))
    if store is not None:
        store.put(floor)
    return floor
