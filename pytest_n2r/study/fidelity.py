"""Fidelity measured the way tests use a scene: held-out PSNR / SSIM beside the reality-to-field shift of
the built-in detectors (ORB, SIFT, AKAZE: repeatability and interest-point spread, reference image vs field
render at the same held-out pose). ``n2r info --shift`` and ``benchmarks/fidelity.py`` print it.

The reference image is the stored photo, or the exact render for a fitted demo scene
(:func:`pytest_n2r.relation.floor.reference_kind`). Scores are the metrics' (1 is ideal for both), with the points
of the two images paired as the paper pairs them, by the identity between two images of one pose
(:data:`~pytest_n2r.study.suts.SAME_POSE_METRICS_BY_KIND`): the photo's points where the field rendered nothing
count. A relation's own field floor (the plugin's) is measured with the relation's metric instead, which with a
depth mapping leaves those points out of both sides, as the relation's examples do. Beside it, the yardstick:
each detector's repeatability on the capture's nearest other photo brought to the same pose
(:mod:`pytest_n2r.relation.floor.nearby`), what a real image taken nearby scores against the reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..metrics.image_quality import psnr, ssim
from ..relation.floor import (
    FieldFloor,
    FloorStore,
    ShiftSample,
    floor_views,
    json_number,
    measure_floor,
    reference_image,
    reference_kind,
)
from ..render.size import RenderSize
from ..scene.base import Scene
from ..scene.render_cache import RenderCache
from .suts import resolve_sut

__all__ = ["DETECTORS", "FidelityReport", "measure_fidelity"]

#: The detectors the fidelity report measures (built-in SUTs of ``n2r study``).
DETECTORS = ("orb", "sift", "akaze")


@dataclass(frozen=True)
class FidelityReport:
    """``images``: per held-out view, PSNR (dB) and SSIM of the render against the reference image;
    ``floors``: a :class:`~pytest_n2r.relation.floor.FieldFloor` per detector and metric name (``("orb",
    "repeatability")``, ...), each with its nearest-photo samples beside the render's; ``reference``: the
    reference kind (``"photo"``, ``"exact"``, or ``"none"`` with ``reason``)."""

    scene: str
    size: str
    reference: str
    reason: str
    images: tuple[dict, ...]
    floors: dict[tuple[str, str], FieldFloor]

    def mean(self, key: str) -> float:
        values = [row[key] for row in self.images if np.isfinite(row[key])]
        return float(np.mean(values)) if values else float("nan")

    def score(self, detector: str, metric: str) -> float:
        """Mean score of ``detector`` under ``metric`` (``"repeatability"`` or ``"ip_spread"``)."""
        floor = self.floors.get((detector, metric))
        return _mean_score(floor.samples if floor is not None else ())

    def nearby_score(self, detector: str) -> float:
        """Mean repeatability of ``detector`` on the nearest other photo brought to each view's pose (the floors'
        ``nearby`` samples), NaN when undefined or when the scene has no other fitted view to bring."""
        floor = self.floors.get((detector, "repeatability"))
        return _mean_score(floor.nearby if floor is not None else ())

    @property
    def nearby_degrees(self) -> float:
        """How far the nearest other photos were: the median angle between optical axes (NaN without them)."""
        return next((f.nearby_degrees for f in self.floors.values() if f.nearby), float("nan"))

    def to_dict(self) -> dict:
        """Plain JSON-ready values: strict JSON, a value that is not a finite number (no defined sample, the
        infinite PSNR of identical images) is ``None``."""
        return {"scene": self.scene, "size": self.size, "reference": self.reference, "reason": self.reason,
                "images": [{k: json_number(v) if isinstance(v, float) else v for k, v in row.items()}
                           for row in self.images],
                "psnr": json_number(self.mean("psnr")), "ssim": json_number(self.mean("ssim")),
                "detectors": {d: {m: json_number(self.score(d, m)) for m in ("repeatability", "ip_spread")}
                              for d in DETECTORS},
                "floors": [{"detector": d, "metric": m, **f.to_dict()} for (d, m), f in self.floors.items()],
                "nearby": {d: json_number(self.nearby_score(d)) for d in DETECTORS},
                "nearby_degrees": json_number(self.nearby_degrees)}

    def format(self) -> str:
        """Plain-text table (what ``n2r info --shift`` prints)."""
        if self.reference == "none":
            return f"reality-to-field shift n/a: {self.reason}"
        photo = self.reference == "photo"
        against = "the stored photo" if photo else "the exact render"
        column = "nearest photo" if photo else "nearest view"
        n = len(self.images)
        lines = [(f"reality-to-field shift: each detector on {against} vs on the render at the same held-out "
                 f"pose ({self.size} px, mean of {n} view{'s' if n != 1 else ''}; 1 is ideal)"),
                 f"  render vs reference   PSNR {self.mean('psnr'):.2f} dB, SSIM {self.mean('ssim'):.4f}",
                 f"  {'detector':<10}{'repeatability':>15}{'spread':>9}{column:>15}"]
        have = math.isfinite(self.nearby_degrees)
        for d in DETECTORS:
            value = self.nearby_score(d)
            yardstick = f"{value:>15.3f}" if math.isfinite(value) else f"{'undefined' if have else 'n/a':>15}"
            lines.append(f"  {d:<10}{self.score(d, 'repeatability'):>15.3f}{self.score(d, 'ip_spread'):>9.3f}"
                         f"{yardstick}")
        if have:
            other = "photo" if photo else "view's exact render"
            lines.append(f"  {column}: the nearest other fitted {other} (median {self.nearby_degrees:.1f}° "
                         "away) brought to the same pose through the field's depth,\n"
                         "  scored like the render: what an image taken nearby scores")
        else:
            lines.append(f"  {column} n/a: no other fitted view with a reference image")
        return "\n".join(lines)


def _mean_score(samples: tuple[ShiftSample, ...]) -> float:
    scores = [s.score for s in samples if s.valid]
    return float(np.mean(scores)) if scores else float("nan")


def measure_fidelity(scene: Scene, *, size: int | str | None = 480, max_views: int | None = None,
                     store: FloorStore | None = None, cache: RenderCache | None = None) -> FidelityReport:
    """PSNR / SSIM and the detector shift of ``scene`` on its held-out views (at most ``max_views``), rendered
    ``size`` pixels on the longer side (``None``: each view's camera)."""
    render_size = None if size is None else RenderSize.parse(size)
    kind, reason = reference_kind(scene)
    size_text = "view size" if render_size is None else str(render_size)
    if kind == "none":
        return FidelityReport(scene.name, size_text, kind, reason, (), {})
    cache = cache if cache is not None else RenderCache(None)
    images = []
    for view in floor_views(scene, max_views):
        camera = view.camera if render_size is None else render_size.apply(view.camera)
        # depth and opacity too: the floors bring the nearest other photo to the pose through them (one pass)
        render = cache.render(scene, view.c2w, camera, ("rgb", "depth", "opacity")).output("rgb")
        reference = reference_image(scene, view, camera, kind, lambda s, c2w, cam: cache.render(s, c2w, cam))
        images.append({"view": view.name, "psnr": psnr(reference, render), "ssim": ssim(reference, render)})
    floors = {}
    for name in DETECTORS:
        sut = resolve_sut(name, None)
        for key, metric in sut.same_pose_metrics().items():
            floors[name, key] = measure_floor(scene, sut.fn, metric, size=render_size, cache=cache, store=store,
                                              name=name, max_views=max_views, nearby=True)
    return FidelityReport(scene.name, size_text, kind, "", tuple(images), floors)
