"""Scoring a fitted field against the photos of views it was not fitted to (held out), and, at the end of a fit,
against a few of those it was fitted to (training views), with how far each held-out view is from the fitted ones.

Convention
----------
- Renders use :data:`FIT_RENDER`, the renderer's defaults, at each view's own camera and pose (camera to world).
- PSNR in dB and SSIM on RGB in [0, 1], as :mod:`pytest_n2r.metrics.image_quality` computes them; a view
  without a photo is skipped, and no view at all scores ``None`` (nothing to compare is not a score).
- A training view is scored exactly as a held-out one: the field's render, with no per-photo colour gain, against
  its photo.
- How far a held-out view is from the fit: its nearest training view by :mod:`pytest_n2r.geometry.view_gap` (the
  field floor's nearby photo is chosen the same way), the angle between their optical axes in degrees and the
  distance between their centres in reference lengths. Frames of a video held out between fitted frames lie a few
  degrees and hundredths of a reference length from them, photos of a capture walked around its subject several
  times as far (``docs/scene-field.md``, "Reading a fit's scores").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..data.capture import CapturedView
from ..field.grid import SceneField
from ..geometry.view_gap import nearest_pose
from ..render.field_render import FieldRenderer, RenderSettings

__all__ = ["FIT_RENDER", "TRAIN_SCORED", "evaluate_views", "final_scores", "mean_scores", "nearest_fitted",
           "spread_out"]

#: Render settings used for held-out evaluation during and after a fit.
FIT_RENDER = RenderSettings()
#: How many training views a fit scores at its end (spread along the capture; all where there are fewer). Measured
#: on the 2-core host under load: 0.67 s after the fox's 10-minute fit (270×480), 0.43 s after a portrait video's
#: 2-minute fit; see ``docs/scene-field.md`` ("Reading a fit's scores").
TRAIN_SCORED = 8


def evaluate_views(
    field: SceneField, views: Sequence[CapturedView], settings: RenderSettings = FIT_RENDER
) -> list[dict]:
    """PSNR (dB) and SSIM of the field's render against each view's real image."""
    from ..metrics.image_quality import psnr, ssim

    renderer = FieldRenderer(field, settings)
    rows = []
    for view in views:
        if view.image is None:
            continue
        rgb = renderer.render(view.c2w, view.camera, ("rgb",))["rgb"]
        rows.append({"view": view.name, "psnr": round(psnr(view.image, rgb), 3),
                     "ssim": round(ssim(view.image, rgb), 4)})
    return rows


def mean_scores(rows: list[dict]) -> dict:
    """The mean PSNR and SSIM of :func:`evaluate_views`'s rows; ``None`` for both when there are none.

    >>> mean_scores([{"psnr": 20.0, "ssim": 0.5}, {"psnr": 30.0, "ssim": 0.7}])
    {'psnr': 25.0, 'ssim': 0.6}
    >>> mean_scores([])
    {'psnr': None, 'ssim': None}
    """
    if not rows:
        return {"psnr": None, "ssim": None}
    return {"psnr": round(float(np.mean([r["psnr"] for r in rows])), 3),
            "ssim": round(float(np.mean([r["ssim"] for r in rows])), 4)}


def spread_out(views: Sequence[CapturedView], count: int = TRAIN_SCORED) -> list[CapturedView]:
    """``count`` of ``views`` evenly spread along them, first and last included (all of them where there are no more).

    >>> spread_out(list("abcdefghij"), 4)
    ['a', 'd', 'g', 'j']
    """
    if len(views) <= count:
        return list(views)
    return [views[int(i)] for i in np.linspace(0, len(views) - 1, count).round()]


def nearest_fitted(heldout: Sequence[CapturedView], train: Sequence[CapturedView],
                   reference_length: float) -> list[dict]:
    """For each held-out view, its nearest training view (``nearest``, its name), the angle between their optical
    axes (``nearest_degrees``) and the distance between their centres (``nearest_distance``, reference lengths of
    ``reference_length`` scene units); see the Convention."""
    out = []
    for view in heldout:
        index, degrees, distance = nearest_pose(view.c2w, [v.c2w for v in train], reference_length)
        out.append({"nearest": train[index].name, "nearest_degrees": round(degrees, 3),
                    "nearest_distance": round(distance, 4)})
    return out


def final_scores(field: SceneField, heldout: Sequence[CapturedView], train: Sequence[CapturedView],
                 reference_length: float) -> dict:
    """The end of a fit's report: ``heldout`` (:func:`evaluate_views` of the ``heldout`` views, each row with its
    :func:`nearest_fitted` training view), their mean ``psnr`` and ``ssim``, ``nearest_fitted`` (the median and
    least ``degrees`` and ``distance`` over those rows; ``None`` without rows), and ``train_scored``,
    ``train_psnr``, ``train_ssim``: the same scores of :data:`TRAIN_SCORED` training views (:func:`spread_out`)."""
    scored = [view for view in heldout if view.image is not None]  # the views evaluate_views scores
    rows = [{**row, **gap} for row, gap in zip(evaluate_views(field, scored),
                                               nearest_fitted(scored, train, reference_length))]
    summary = None
    if rows:
        summary = {what: {"median": round(float(np.median([r[f"nearest_{what}"] for r in rows])), digits),
                          "min": min(r[f"nearest_{what}"] for r in rows)} for what, digits in (("degrees", 3),
                                                                                             ("distance", 4))}
    trained = evaluate_views(field, spread_out(train))
    scores = mean_scores(trained)
    return {"heldout": rows, **mean_scores(rows), "nearest_fitted": summary, "train_scored": trained,
            "train_psnr": scores["psnr"], "train_ssim": scores["ssim"]}
