"""Scoring a fitted field against the exact demo scene, shared by the benchmark scripts (imported as ``_scoring``:
scripts run from this folder).

PSNR and SSIM of the field's render against the exact render at each pose, and the repeatability (2 px, the
study's parameters) of ORB, SIFT and AKAZE between the exact image and the field's, as the fidelity report
measures a scene's shift. A detector that finds nothing to compare on a view (tiny images, a blank render)
leaves that view undefined: it is counted apart, never scored, and a mean over no defined view is ``None``
("nothing to compare"), not 0 and not a NaN from averaging an empty selection.

Given the poses the field was fitted on, the score also says how much of each view no fitted photo saw
(:func:`unseen_mask`: surface the field could only guess) and the PSNR over the rest, so that a view framing
what the capture missed is told apart from a field that renders what it saw poorly.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from pytest_n2r.geometry import CameraStack, backproject, inside_image, pixel_grid
from pytest_n2r.metrics.image_quality import psnr, ssim
from pytest_n2r.relation.floor.reference import shift_sample
from pytest_n2r.render.field_render import FieldRenderer
from pytest_n2r.study.fidelity import DETECTORS
from pytest_n2r.study.suts import resolve_sut


def defined_mean(values: list[float]) -> dict:
    """``{"mean": mean of the finite values or None, "defined": how many, "n": of how many}``."""
    finite = [v for v in values if np.isfinite(v)]
    return {"mean": round(float(np.mean(finite)), 4) if finite else None, "defined": len(finite), "n": len(values)}


#: A surface point counts as hidden from a fitted photo when the photo's exact z-depth at its pixel is nearer than
#: the point's own by more than this fraction (the depths of one surface agree to ~1e-6; a pixel's cell spans less).
OCCLUSION_SLACK = 0.01


class FittedPhotos:
    """The poses a field was fitted on (``(c2w, camera)`` pairs) with their exact z-depths in ``scene``."""

    def __init__(self, scene, poses) -> None:
        self.stack = CameraStack.of([camera for _, camera in poses], [c2w for c2w, _ in poses])
        self.depths = [scene.render(c2w, camera, ("depth",)).depth for c2w, camera in poses]

    def unseen_mask(self, view) -> np.ndarray:
        """``H x W`` bool of the exact ``view`` (rendered with ``depth`` and ``opacity``): the pixels whose surface
        point (at the pixel centre's z-depth) no fitted photo sees: behind each photo, outside its image, or hidden
        there by a nearer surface (:data:`OCCLUSION_SLACK`). Pixels that hit no surface are never unseen."""
        solid = view.opacity >= 0.5
        points = backproject(pixel_grid(view.camera)[solid], view.depth[solid].astype(np.float64), view.camera,
                             view.c2w)
        u, v, z = self.stack.project(points)
        seen = (z > 0) & inside_image(u, v, self.stack.size[:, 0, None], self.stack.size[:, 1, None])
        for k, depth in enumerate(self.depths):
            at = np.flatnonzero(seen[k])
            iu = np.minimum(np.floor(u[k, at] + 0.5).astype(np.intp), depth.shape[1] - 1)
            iv = np.minimum(np.floor(v[k, at] + 0.5).astype(np.intp), depth.shape[0] - 1)
            seen[k, at] = depth[iv, iu] >= z[k, at] * (1 - OCCLUSION_SLACK)
        unseen = np.zeros(solid.shape, dtype=bool)
        unseen[solid] = ~seen.any(axis=0)
        return unseen


def score_exact(scene, field, poses, detectors: tuple[str, ...] = DETECTORS, *,
                fitted: FittedPhotos | None = None) -> dict:
    """Mean PSNR (dB), SSIM and each detector's repeatability of ``field``'s renders against ``scene``'s exact
    renders at ``poses`` (``(c2w, camera)`` pairs), and each view's PSNR (``psnr_views``). With the ``fitted``
    photos, also the mean share of each view's pixels they did not see (``unseen``, :meth:`FittedPhotos.unseen_mask`)
    and the mean PSNR over the other pixels (``psnr_seen``)."""
    renderer = FieldRenderer(field)
    suts = {name: resolve_sut(name, None) for name in detectors}
    rows: dict[str, list[float]] = {"psnr": [], "ssim": [], "unseen": [], "psnr_seen": [],
                                    **{name: [] for name in detectors}}
    for k, (c2w, camera) in enumerate(poses):
        want = scene.render(c2w, camera, ("rgb", "depth", "opacity"))
        got = replace(want, rgb=renderer.render(c2w, camera, ("rgb",))["rgb"])
        rows["psnr"].append(psnr(want.rgb, got.rgb))
        rows["ssim"].append(ssim(want.rgb, got.rgb))
        if fitted is not None:
            seen = ~fitted.unseen_mask(want)
            rows["unseen"].append(1.0 - float(seen.mean()))
            rows["psnr_seen"].append(psnr(want.rgb[seen][None], got.rgb[seen][None]) if seen.any() else math.nan)
        for name, sut in suts.items():
            sample = shift_sample(sut.metrics()["repeatability"], sut.fn(want.rgb), sut.fn(got.rgb), want, got, str(k))
            rows[name].append(sample.score if sample.valid else float("nan"))
    out = {"psnr": round(float(np.mean(rows["psnr"])), 2), "ssim": round(float(np.mean(rows["ssim"])), 4),
           "n": len(poses), "psnr_views": [round(float(x), 2) for x in rows["psnr"]]}
    if fitted is not None:
        seen_psnrs = [x for x in rows["psnr_seen"] if not math.isnan(x)]  # a view wholly unseen compares nothing
        out.update(unseen=round(float(np.mean(rows["unseen"])), 4),
                   psnr_seen=round(float(np.mean(seen_psnrs)), 2) if seen_psnrs else None,
                   unseen_views=[round(x, 4) for x in rows["unseen"]],
                   psnr_seen_views=[None if math.isnan(x) else round(float(x), 2) for x in rows["psnr_seen"]])
    return {**out, **{name: defined_mean(rows[name]) for name in detectors}}


def format_repeatability(entry: dict) -> str:
    """``0.412`` when every view is defined, ``0.412 (4 of 6)`` when some are not, ``n/a (0 of 6)`` when none."""
    if entry["mean"] is None:
        return f"n/a (0 of {entry['n']})"
    text = f"{entry['mean']:.3f}"
    return text if entry["defined"] == entry["n"] else f"{text} ({entry['defined']} of {entry['n']})"


def format_repeatabilities(score: dict, sep: str) -> str:
    """Each detector's :func:`format_repeatability` in ``score``, in :data:`DETECTORS` order, joined by ``sep``."""
    return sep.join(format_repeatability(score[name]) for name in DETECTORS)
