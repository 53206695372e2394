"""The field floor: what a fitted scene's field alone does to a SUT's metric (the paper's reality-to-field
shift), measured once per scene, SUT, metric and render size, and cached.

For every held-out view of a fitted scene, the SUT runs on the view's *reference image* and on the field's
render at the same pose and size, and the metric compares the two outputs as if they were a relation's
source and follow-up. The reference image is, in this order:

- ``"photo"``: the real photo the scene file stores (``n2r fit`` stores a JPEG copy of every photo unless
  ``--no-images``), resized to the render size;
- ``"exact"``: for a fitted demo scene (``demo:wall-field``), the exact scene's render at the same pose:
  the truth the field was fitted to.

An exact scene has no field, so no floor; a fitted scene without photos or exact twin has no reference.
Both are reported as unavailable with the reason, never as a floor of 0.

The floor is the mean deviation over the held-out views whose metric is defined. A relation whose ``eps``
is below it asks the SUT to agree with itself across two renders more closely than it agrees between the
photo and the render of one pose: it then tests the scene field, not the SUT.

Only held-out views count: the field was fitted to the training photos, so their shift understates what
the field does at the new poses relations render.

Convention
    Deviations are the metric's (``|score - ideal|``, larger is worse), unitless. Render sizes follow
    :class:`~pytest_n2r.render.size.RenderSize` (``None``: each view's own camera).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Callable
from dataclasses import asdict, dataclass
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .cache import RenderCache
from .data.atomic import atomic_write_text
from .errors import MetricUndefined
from .geometry import Camera
from .metrics.base import Metric
from .render.size import RenderSize
from .render.view import RenderedView
from .scene.base import Scene, SceneView, normalize_outputs

__all__ = [
    "ExactComparison",
    "FieldFloor",
    "FloorStore",
    "ShiftSample",
    "annotate_relation",
    "annotation_lines",
    "compare_exact",
    "exact_twin",
    "floor_views",
    "measure_floor",
    "reference_image",
    "reference_kind",
    "shift_sample",
    "sut_name",
]

#: Bumped when the measurement changes, so cached floors of an older measurement are not reused.
FLOOR_VERSION = 1


# -- one pose -------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ShiftSample:
    """The metric between the SUT's output on a view's reference image and on its render at the same pose:
    ``score`` and ``deviation`` (NaN and ``valid=False`` with a ``reason`` when the metric is undefined)."""

    view: str
    score: float
    deviation: float
    valid: bool
    reason: str = ""


def shift_sample(metric: Metric, out_reference: Any, out_render: Any, reference: RenderedView,
                 render: RenderedView, view: str) -> ShiftSample:
    """Score the SUT's output on the reference image (``reference``, the render's geometry with the real
    pixels) against its output on the ``render`` of the same pose, as a relation's source and follow-up."""
    try:
        result = metric.compute(out_reference, out_render, reference, render)
    except MetricUndefined as exc:
        return ShiftSample(view, math.nan, math.nan, False, str(exc))
    if not result.valid:
        return ShiftSample(view, math.nan, math.nan, False, str(result.details.get("reason", "undefined")))
    return ShiftSample(view, float(result.score), float(result.deviation), True)


def exact_twin(scene: Scene) -> Scene | None:
    """The exact scene a fitted demo scene was fitted to (``demo:wall-field`` → ``demo:wall``), else ``None``.

    Recognized by the recipe the fitted demo file stores (``report["demo_recipe"]["scene"]``)."""
    report = getattr(scene, "report", None)
    if getattr(scene, "is_exact", False) or not isinstance(report, dict):
        return None
    recipe = report.get("demo_recipe")
    name = recipe.get("scene") if isinstance(recipe, dict) else None
    if not isinstance(name, str):
        return None
    try:
        from .demo import demo_scene_names, ground_truth
    except ImportError:  # a build without demo scenes
        return None
    return ground_truth(name) if name in demo_scene_names() else None


def reference_kind(scene: Scene) -> tuple[str, str]:
    """``(kind, reason)``: ``"photo"`` when held-out views store photos, ``"exact"`` for a fitted demo scene,
    else ``"none"`` with the reason there is no floor."""
    if getattr(scene, "is_exact", False):
        return "none", "an exact scene renders the truth: there is no field, so no field floor"
    views = floor_views(scene)
    if not views:
        return "none", (f"scene {scene.name!r} has no held-out view (the training views were fitted, so they "
                        "would understate the floor)")
    if all(v.image is not None for v in views):
        return "photo", ""
    if exact_twin(scene) is not None:
        return "exact", ""
    return "none", (f"scene {scene.name!r} stores no photos of its held-out views (fitted with --no-images, or "
                    "loaded with images=False), so there is nothing real to compare its renders with")


def floor_views(scene: Scene, max_views: int | None = None) -> list[SceneView]:
    """The held-out views of ``scene``, at most ``max_views`` spread over the trajectory."""
    views = [v for v in scene.views if v.split == "heldout"]
    if max_views is not None and len(views) > max_views:
        views = [views[i] for i in np.linspace(0, len(views) - 1, max_views).round().astype(int)]
    return views


def reference_image(scene: Scene, view: SceneView, camera: Camera, kind: str,
                    render: Callable[[Scene, np.ndarray, Camera], RenderedView] | None = None) -> np.ndarray:
    """The reference image of ``view`` at ``camera``'s size (H×W×3 uint8 RGB): its stored photo resized
    with area averaging (``kind="photo"``), or the exact twin's render (``kind="exact"``) through
    ``render(scene, c2w, camera)`` (default: the scene's own render)."""
    import cv2

    if kind == "photo":
        image = view.image
        if image is None:
            raise ValueError(f"view {view.name!r} stores no photo")
        if image.shape[:2] != (camera.height, camera.width):
            image = cv2.resize(image, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
        image = image.view()
        image.setflags(write=False)  # a SUT gets it as it gets a cached render: it may not draw on the photo
        return image
    twin = scene if getattr(scene, "is_exact", False) else exact_twin(scene)
    if kind != "exact" or twin is None:
        raise ValueError(f"scene {scene.name!r} has no reference image of kind {kind!r}")
    do = render or (lambda s, c2w, cam: s.render(c2w, cam, ("rgb",)))
    return do(twin, view.c2w, camera).rgb


# -- the floor ------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FieldFloor:
    """The reality-to-field shift of one SUT and metric on one scene at one render size.

    ``reference`` is ``"photo"``, ``"exact"`` or ``"none"`` (then ``reason`` says why there is no floor);
    ``samples`` holds one :class:`ShiftSample` per held-out view. :attr:`value` is the mean deviation of
    the defined samples (NaN when none is defined)."""

    scene: str
    sut: str
    metric: str
    size: str
    reference: str
    samples: tuple[ShiftSample, ...] = ()
    reason: str = ""
    key: str = ""

    @property
    def deviations(self) -> list[float]:
        return [s.deviation for s in self.samples if s.valid]

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
        text = (f"field floor {self.value:.3g} ({against} vs field render at the same pose, mean of "
                f"{self.n} held-out view{'s' if self.n != 1 else ''}, max {self.max:.3g}"
                + (f", {undefined} undefined" if undefined else "") + ")")
        if eps is not None and self.above(eps):
            text += (f"; WARNING: eps {eps:g} is below the field floor: this relation tests the scene field, "
                     "not the SUT")
        return text

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN as ``None``), with the summary values for readers of reports."""
        d = asdict(self)
        d["samples"] = [{**s, "score": _json_num(s["score"]), "deviation": _json_num(s["deviation"])}
                        for s in d["samples"]]
        d.update(value=_json_num(self.value), max=_json_num(self.max), n=self.n)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FieldFloor:
        samples = tuple(ShiftSample(s["view"], _num(s["score"]), _num(s["deviation"]), bool(s["valid"]),
                                    s.get("reason", "")) for s in d.get("samples", ()))
        return cls(d["scene"], d["sut"], d["metric"], d["size"], d["reference"], samples, d.get("reason", ""),
                   d.get("key", ""))


def _json_num(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _num(x: float | None) -> float:
    return math.nan if x is None else float(x)


class FloorStore:
    """Measured floors, in memory and (with a ``directory``) on disk as JSON, one file per key."""

    def __init__(self, directory: str | os.PathLike | None = None):
        self.directory = Path(directory) if directory is not None else None
        self._memory: dict[str, FieldFloor] = {}

    def get(self, key: str) -> FieldFloor | None:
        floor = self._memory.get(key)
        if floor is None and self.directory is not None:
            path = self.directory / f"{key}.json"
            try:
                floor = FieldFloor.from_dict(json.loads(path.read_text()))
            except (OSError, ValueError, KeyError, TypeError):  # absent, or torn by a crash: measure again
                return None
            self._memory[key] = floor
        return floor

    def put(self, floor: FieldFloor) -> None:
        self._memory[floor.key] = floor
        if self.directory is not None:
            atomic_write_text(self.directory / f"{floor.key}.json", json.dumps(floor.to_dict(), indent=1) + "\n")


def sut_name(sut: Callable[..., Any]) -> str:
    """``module:qualname`` of a SUT callable (its class's for a callable object)."""
    target = sut if hasattr(sut, "__qualname__") else type(sut)
    return f"{getattr(target, '__module__', '?')}:{getattr(target, '__qualname__', type(sut).__name__)}"


def _digest_output(output: Any) -> str:
    """A digest of a SUT output (keypoint lists as their coordinates, arrays with shape and dtype)."""
    h = hashlib.sha256()
    if isinstance(output, (list, tuple)) and output and all(hasattr(k, "pt") for k in output):
        output = np.array([k.pt for k in output], dtype=np.float64)
    if hasattr(output, "detach") and hasattr(output, "cpu"):
        output = output.detach().cpu().numpy()
    if isinstance(output, np.ndarray):
        h.update(f"{output.shape}/{output.dtype}".encode())
        h.update(np.ascontiguousarray(output).tobytes())
    else:
        h.update(repr(output).encode())
    return h.hexdigest()


def measure_floor(scene: Scene, sut: Callable[[np.ndarray], Any], metric: Metric, *,
                  size: RenderSize | None = None, cache: RenderCache | None = None,
                  store: FloorStore | None = None, name: str | None = None,
                  max_views: int | None = 12) -> FieldFloor:
    """The field floor of ``sut`` (an H×W×3 uint8 RGB image → its output) under ``metric`` on ``scene``,
    rendered at ``size`` (``None``: each view's camera) on at most ``max_views`` held-out views.

    Renders go through ``cache`` (default: none); ``store`` keeps measured floors keyed by the scene's
    content hash, the exact twin's, the SUT (``name``, default :func:`sut_name`, and a digest of its output
    on the first reference image, so an edited SUT whose output changes there is measured again), the
    metric's ``repr``, the size, the views and :data:`FLOOR_VERSION`.
    """
    name = name or sut_name(sut)
    size_text = "view size" if size is None else str(size)
    kind, reason = reference_kind(scene)
    if kind == "none":
        return FieldFloor(scene.name, name, repr(metric), size_text, kind, reason=reason)
    views = floor_views(scene, max_views)
    render_cache = cache if cache is not None else RenderCache(None)
    outputs = normalize_outputs(("rgb", *(getattr(metric, "needs", ()) or ())))

    def camera_of(view: SceneView) -> Camera:
        return view.camera if size is None else size.apply(view.camera)

    def render(s: Scene, c2w: np.ndarray, camera: Camera) -> RenderedView:
        return render_cache.render(s, c2w, camera, outputs if s is scene else ("rgb",))

    references = (reference_image(scene, v, camera_of(v), kind, render) for v in views)
    first = next(references)
    first_output = sut(first)
    twin = exact_twin(scene) if kind == "exact" else None
    spec = {"floor": FLOOR_VERSION, "pytest_n2r": __version__, "scene": scene.content_hash,
            "twin": twin.content_hash if twin is not None else None, "sut": name,
            "probe": _digest_output(first_output), "metric": repr(metric), "size": size_text,
            "views": [v.name for v in views], "reference": kind}
    key = hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:32]
    if store is not None and (known := store.get(key)) is not None:
        return known
    samples = []
    for view, image in zip(views, chain([first], references)):
        rendered = render(scene, view.c2w, camera_of(view))
        real = RenderedView(rendered.camera, rendered.c2w, rgb=image, depth=rendered.depth,
                            opacity=rendered.opacity)
        out_real = first_output if image is first else sut(image)
        samples.append(shift_sample(metric, out_real, sut(rendered.rgb), real, rendered, view.name))
    floor = FieldFloor(scene.name, name, repr(metric), size_text, kind, tuple(samples), key=key)
    if store is not None:
        store.put(floor)
    return floor



# -- exact vs fitted (demo scenes) ----------------------------------------------------------------------

#: How many of a relation's examples are replayed on the exact twin (the first ones, in draw order): each
#: costs an exact render (about 1-2 s at 480x270 on a laptop CPU, then cached) and two SUT calls.
EXACT_REPLAY_EXAMPLES = 10


@dataclass(frozen=True)
class ExactComparison:
    """A relation's examples on a fitted demo scene replayed at the same poses on its exact twin:
    ``pairs`` of ``(fitted deviation, exact deviation)`` where both are defined; ``undefined`` examples
    whose metric was undefined on the exact renders; ``skipped`` ones that cannot be replayed (mutations,
    interpolated source views)."""

    pairs: tuple[tuple[float, float], ...]
    undefined: int = 0
    skipped: int = 0

    @property
    def n(self) -> int:
        return len(self.pairs)

    def means(self) -> tuple[float, float]:
        """Mean deviation ``(fitted, exact)`` over the pairs (NaN when there is none)."""
        if not self.pairs:
            return math.nan, math.nan
        fitted, exact = np.asarray(self.pairs).T
        return float(fitted.mean()), float(exact.mean())

    def describe(self) -> str:
        extra = "".join(f", {k} {n}" for k, n in (("undefined on exact renders", self.undefined),
                                                    ("not replayable", self.skipped)) if n)
        if not self.pairs:
            return f"exact vs fitted: no example replayed{extra}"
        fitted, exact = self.means()
        return (f"same poses on exact renders: mean deviation {exact:.3g} exact vs {fitted:.3g} fitted "
                f"(the field adds {fitted - exact:+.3g}; {self.n} example{'s' if self.n != 1 else ''}{extra})")

    def to_dict(self) -> dict[str, Any]:
        fitted, exact = self.means()
        return {"pairs": [list(p) for p in self.pairs], "undefined": self.undefined, "skipped": self.skipped,
                "n": self.n, "fitted_mean": _json_num(fitted), "exact_mean": _json_num(exact)}


def compare_exact(scene: Scene, sut: Callable[[np.ndarray], Any], metric: Metric, records: list[dict[str, Any]],
                  camera_of: Callable[[SceneView], Camera], length_scale: float, *,
                  cache: RenderCache | None = None, limit: int = EXACT_REPLAY_EXAMPLES) -> ExactComparison | None:
    """Replay the first ``limit`` ``records`` of a relation on ``scene`` (``view`` name, ``transform`` fields,
    ``deviation``) on the scene's exact twin; ``None`` when ``scene`` has none. ``length_scale`` converts the
    transforms' translations to scene units, ``camera_of`` gives the render camera of a source view."""
    from .geometry import Transform

    twin = exact_twin(scene)
    if twin is None:
        return None
    render_cache = cache if cache is not None else RenderCache(None)
    outputs = normalize_outputs(("rgb", *(getattr(metric, "needs", ()) or ())))
    by_name = {v.name: v for v in scene.views}
    sources: dict[str, tuple[RenderedView, Any]] = {}
    pairs, undefined, skipped = [], 0, 0
    accepted = [r for r in records if r.get("status", "accepted") == "accepted"]  # the draws that were tests
    for record in accepted[:limit]:
        view = by_name.get(record["view"])
        transform = record["transform"]
        if view is None or transform is None or "mutation" in transform:
            skipped += 1
            continue
        if view.name not in sources:
            rendered = render_cache.render(twin, view.c2w, camera_of(view), outputs)
            sources[view.name] = (rendered, sut(rendered.rgb))
        source, out_source = sources[view.name]
        follow_c2w = Transform(**transform).apply(view.c2w, length_scale)
        follow = render_cache.render(twin, follow_c2w, camera_of(view), outputs)
        sample = shift_sample(metric, out_source, sut(follow.rgb), source, follow, view.name)
        if sample.valid:
            pairs.append((float(record["deviation"]), sample.deviation))
        else:
            undefined += 1
    return ExactComparison(tuple(pairs), undefined, skipped)


# -- beside a relation's result (the plugin) ------------------------------------------------------------

_STORES: dict[Path | None, FloorStore] = {}


def annotate_relation(scene: Scene, sut: Callable[[np.ndarray], Any], relation: Any, records: list[dict[str, Any]],
                      *, size: RenderSize | None, cache: RenderCache | None,
                      cache_dir: Path | None) -> dict[str, Any] | None:
    """What the plugin shows beside a relation's result on ``scene`` (``None`` on an exact scene): the field
    floor of the relation's SUT, metric and render size, whether ``eps`` is below it, and on a fitted demo
    scene the relation's examples replayed on exact renders. Plain JSON-ready data; a floor that cannot be
    measured (the SUT raises on a photo, ...) is reported with the reason, never raised."""
    if getattr(scene, "is_exact", False):
        return None
    from .strategies import transform_units

    directory = None if cache_dir is None else Path(cache_dir) / "floors"
    store = _STORES.setdefault(directory, FloorStore(directory))
    eps = float(relation.eps)
    try:
        floor = measure_floor(scene, sut, relation.metric, size=size, cache=cache, store=store)
    except Exception as exc:  # noqa: BLE001 -- an annotation: what went wrong is said, the verdict stands
        floor = FieldFloor(scene.name, sut_name(sut), repr(relation.metric), str(size), "none",
                           reason=f"measuring it failed: {type(exc).__name__}: {exc}")
    out: dict[str, Any] = {"floor": floor.to_dict(), "line": floor.describe(eps), "below_floor": floor.above(eps)}
    try:
        length = scene.length_scale(transform_units(relation.transform))
        comparison = compare_exact(scene, sut, relation.metric, records,
                                   lambda v: v.camera if size is None else size.apply(v.camera), length,
                                   cache=cache)
    except Exception as exc:  # noqa: BLE001 -- as above
        out["exact_line"] = f"exact vs fitted: replay failed: {type(exc).__name__}: {exc}"
    else:
        if comparison is not None:
            out["exact"], out["exact_line"] = comparison.to_dict(), comparison.describe()
    return out


def annotation_lines(annotation: dict[str, Any] | None) -> list[tuple[str, bool]]:
    """``(line, is_warning)`` pairs to print under a relation's summary line."""
    if not annotation:
        return []
    lines = [(annotation["line"], bool(annotation["below_floor"]))]
    if annotation.get("exact_line"):
        lines.append((annotation["exact_line"], False))
    return lines
