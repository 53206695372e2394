"""Exact vs fitted: a relation's examples on a fitted demo scene replayed at the same poses on its exact
twin, so a report shows how much of a deviation the scene field adds."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...geometry import Camera
from ...metrics.base import Metric
from ...render.view import RenderedView
from ...scene.base import Scene, SceneView, normalize_outputs
from ...scene.render_cache import RenderCache
from ..kept_results import repainted_key
from ..outputs import sut_image
from ..record import ExampleRecord
from .measure import json_number
from .reference import exact_twin, shift_sample

__all__ = ["EXACT_REPLAY_EXAMPLES", "ExactComparison", "compare_exact"]

#: How many of a relation's examples are replayed on the exact twin (the first ones, in draw order): each
#: costs an exact render (about 1-2 s at 480x270 on a laptop CPU, then cached) and two SUT calls.
EXACT_REPLAY_EXAMPLES = 10


@dataclass(frozen=True)
class ExactComparison:
    """A relation's examples on a fitted demo scene replayed at the same poses on its exact twin (a mutation's
    on the exact source render, mutated): ``pairs`` of ``(fitted deviation, exact deviation)`` where both are
    defined; ``undefined`` examples whose metric was undefined on the exact renders; ``skipped`` ones that cannot
    be replayed (interpolated source views, which the twin has no view of)."""

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
                                                    ("not replayable (interpolated source views)",
                                                     self.skipped)) if n)
        if not self.pairs:
            return f"exact vs fitted: no example replayed{extra}"
        fitted, exact = self.means()
        return (f"same poses on exact renders: mean deviation {exact:.3g} exact vs {fitted:.3g} fitted "
                f"(the field adds {fitted - exact:+.3g}; {self.n} example{'s' if self.n != 1 else ''}{extra})")

    def to_dict(self) -> dict[str, Any]:
        fitted, exact = self.means()
        return {"pairs": [list(p) for p in self.pairs], "undefined": self.undefined, "skipped": self.skipped,
                "n": self.n, "fitted_mean": json_number(fitted), "exact_mean": json_number(exact)}


def compare_exact(scene: Scene, sut: Callable[[np.ndarray], Any], metric: Metric, records: list[ExampleRecord],
                  camera_of: Callable[[SceneView], Camera], *,
                  cache: RenderCache | None = None, limit: int = EXACT_REPLAY_EXAMPLES) -> ExactComparison | None:
    """Replay the first ``limit`` accepted ``records`` of a relation on ``scene`` (source view by name, pose
    change in its recorded units, deviation) on the scene's exact twin; ``None`` when ``scene`` has none.
    ``camera_of`` gives the render camera of a source view. A keypoint metric's results on the exact renders are
    kept in ``cache`` (:func:`~pytest_n2r.relation.kept_results.kept_result`): a later session takes them when the
    SUT's outputs are the same."""
    twin = exact_twin(scene)
    if twin is None:
        return None
    render_cache = cache if cache is not None else RenderCache(None)
    outputs = normalize_outputs(("rgb", *(getattr(metric, "needs", ()) or ())))
    by_name = {v.name: v for v in scene.views}
    sources: dict[str, tuple[RenderedView, str, Any]] = {}
    pairs, undefined, skipped = [], 0, 0
    accepted = [r for r in records if r.valid]  # the draws that were tests
    for record in accepted[:limit]:
        view = by_name.get(record.view)
        if view is None or not record.replayable:
            skipped += 1
            continue
        if view.name not in sources:
            rendered, key = render_cache.render_keyed(twin, view.c2w, camera_of(view), outputs)
            sources[view.name] = (rendered, key, sut(sut_image(rendered, "source")))
        source, source_key, out_source = sources[view.name]
        tau = record.follow_up()
        follow_key: str | None
        if tau.moves_camera:
            follow_c2w = tau.apply(view.c2w, scene.length_scale(tau.units))
            follow, follow_key = render_cache.render_keyed(twin, follow_c2w, camera_of(view), outputs)
        else:  # a mutation: the exact source render, mutated as the fitted one was
            follow = tau.apply_to_view(source)
            follow_key = repainted_key(source, source_key, follow)
        kept = (render_cache, source_key, follow_key) if follow_key is not None else None
        sample = shift_sample(metric, out_source, sut(sut_image(follow, "follow-up")), source, follow, view.name,
                              kept=kept)
        if sample.valid:
            pairs.append((float(record.deviation), sample.deviation))
        else:
            undefined += 1
    return ExactComparison(tuple(pairs), undefined, skipped)
