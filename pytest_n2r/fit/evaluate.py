"""Scoring a fitted field against the photos of views it was not fitted to (held out).

Convention
----------
- Renders use :data:`FIT_RENDER`, the renderer's defaults, at each view's own camera and pose (camera to world).
- PSNR in dB and SSIM on RGB in [0, 1], as :mod:`pytest_n2r.metrics.image_quality` computes them; a view
  without a photo is skipped, and no view at all scores ``None`` (nothing to compare is not a score).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..data.capture import CapturedView
from ..field.grid import SceneField
from ..render.field_render import FieldRenderer, RenderSettings

__all__ = ["FIT_RENDER", "evaluate_views", "mean_scores"]

#: Render settings used for held-out evaluation during and after a fit.
FIT_RENDER = RenderSettings()


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
