"""The reference a field render is compared with: a held-out view's stored photo, or for a fitted demo scene
its exact twin's render at the same pose; and the metric between the SUT's outputs on the two (one
:class:`ShiftSample` per pose)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import MetricUndefined
from ...geometry import Camera
from ...metrics.base import Metric, MetricResult
from ...render.view import RenderedView
from ...scene.base import Scene, SceneView
from ...scene.render_cache import RenderCache
from ..kept_results import kept_result
from ..outputs import sut_image

__all__ = ["ShiftSample", "exact_twin", "floor_views", "reference_image", "reference_kind", "shift_sample"]


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
                 render: RenderedView, view: str, *, kept: tuple[RenderCache, str, str] | None = None) -> ShiftSample:
    """Score the SUT's output on the reference image (``reference``, the render's geometry with the real
    pixels) against its output on the ``render`` of the same pose, as a relation's source and follow-up.
    ``kept``: a render cache and the render keys of ``reference`` and ``render`` when both are renders, so the
    result an earlier session kept there is taken (:func:`~pytest_n2r.relation.kept_results.kept_result`)."""

    def compute() -> MetricResult:
        return metric.compute(out_reference, out_render, reference, render)

    try:
        result = compute() if kept is None else kept_result(kept[0], metric, kept[1], kept[2], out_reference,
                                                             out_render, compute)
    except MetricUndefined as exc:
        return ShiftSample(view, math.nan, math.nan, False, str(exc))
    if not result.valid:
        return ShiftSample(view, math.nan, math.nan, False, str(result.details.get("reason", "undefined")))
    if not math.isfinite(result.deviation):  # a metric's bug, as the engine calls it: never a floor of NaN
        return ShiftSample(view, math.nan, math.nan, False,
                           f"{metric!r} returned a valid result with deviation {result.deviation!r}")
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
    from ...demo import demo_scene_names, ground_truth

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
    return sut_image(do(twin, view.c2w, camera), "reference")
