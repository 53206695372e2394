"""Scoring a fitted field against the exact demo scene, shared by the benchmark scripts (imported as ``_scoring``:
scripts run from this folder).

PSNR and SSIM of the field's render against the exact render at each pose, and the repeatability (2 px, the
study's parameters) of ORB, SIFT and AKAZE between the exact image and the field's, as the fidelity report
measures a scene's shift. A detector that finds nothing to compare on a view (tiny images, a blank render)
leaves that view undefined: it is counted apart, never scored, and a mean over no defined view is ``None``
("nothing to compare"), not 0 and not a NaN from averaging an empty selection.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pytest_n2r.metrics.image_quality import psnr, ssim
from pytest_n2r.relation.floor.reference import shift_sample
from pytest_n2r.render.field_render import FieldRenderer
from pytest_n2r.study.fidelity import DETECTORS
from pytest_n2r.study.suts import resolve_sut


def defined_mean(values: list[float]) -> dict:
    """``{"mean": mean of the finite values or None, "defined": how many, "n": of how many}``."""
    finite = [v for v in values if np.isfinite(v)]
    return {"mean": round(float(np.mean(finite)), 4) if finite else None, "defined": len(finite), "n": len(values)}


def score_exact(scene, field, poses, detectors: tuple[str, ...] = DETECTORS) -> dict:
    """Mean PSNR (dB), SSIM and each detector's repeatability of ``field``'s renders against ``scene``'s exact
    renders at ``poses`` (``(c2w, camera)`` pairs)."""
    renderer = FieldRenderer(field)
    suts = {name: resolve_sut(name, None) for name in detectors}
    rows: dict[str, list[float]] = {"psnr": [], "ssim": [], **{name: [] for name in detectors}}
    for k, (c2w, camera) in enumerate(poses):
        want = scene.render(c2w, camera, ("rgb", "depth", "opacity"))
        got = replace(want, rgb=renderer.render(c2w, camera, ("rgb",))["rgb"])
        rows["psnr"].append(psnr(want.rgb, got.rgb))
        rows["ssim"].append(ssim(want.rgb, got.rgb))
        for name, sut in suts.items():
            sample = shift_sample(sut.metrics()["repeatability"], sut.fn(want.rgb), sut.fn(got.rgb), want, got, str(k))
            rows[name].append(sample.score if sample.valid else float("nan"))
    out = {"psnr": round(float(np.mean(rows["psnr"])), 2), "ssim": round(float(np.mean(rows["ssim"])), 4),
           "n": len(poses)}
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
