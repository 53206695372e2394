"""How much detail a capture can give a field: the training views' pixel footprint on the scene, the grid
size whose voxel matches it, and the finer grid a fit adds where its ladder is too coarse for the photos (what a
machine's memory holds: :mod:`.memory`).

A field cannot show detail finer than its voxel, and a photo shows none finer than its pixel's footprint on
the surface. Where the cameras look closely, the voxel should approach that footprint; a coarser grid blurs
what the photos show (ORB and SIFT respond to exactly that detail), a finer one has nothing more to learn.

Convention
    Footprints are in the field's *normalized* units (scene units divided by the space's ``radius``, so the
    captured region is ``[-1, 1]³``) per pixel: a view's footprint is ``z / fx`` at the median z-depth of the
    sparse points it sees. "Where the cameras look closely" is the 10th percentile of the training views'
    footprints. A grid of ``R`` vertices per axis spans the contracted cube of side ``2·(1 + shell)``, so its
    voxel is ``2·(1 + shell) / (R - 1)`` (:meth:`~pytest_n2r.field.space.SceneSpace.voxel_size`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..data.capture import Capture
from ..field.config import FieldConfig
from ..field.space import SceneSpace
from ..geometry import inside_image, project
from .budget import LONG_BUDGET_RESOLUTIONS

__all__ = ["DETAIL_GRID_MULTIPLE", "DETAIL_STAGE_AT", "LIBRARY_LADDERS", "CaptureDetail", "capture_detail",
           "detailed_config"]

#: Fewest sparse points a view must see for its footprint to count.
MIN_POINTS = 10
#: Percentile of the views' footprints that stands for "where the cameras look closely".
CLOSE_PERCENTILE = 10.0
#: Fraction of the run at which :func:`detailed_config`'s finer grid takes over (the last 30 %, as measured).
DETAIL_STAGE_AT = 0.7
#: The finer grid's size is a multiple of this.
DETAIL_GRID_MULTIPLE = 64
#: The ladders (``resolutions``, ``stage_fractions``) that :func:`detailed_config` extends: the library's own,
#: the default one and a long time budget's (:mod:`pytest_n2r.fit.budget`).
LIBRARY_LADDERS = ((FieldConfig().resolutions, FieldConfig().stage_fractions),
                   (LONG_BUDGET_RESOLUTIONS, FieldConfig().stage_fractions))


@dataclass(frozen=True)
class CaptureDetail:
    """The training views' pixel footprint (normalized units per pixel): ``close`` where the cameras look
    closely (10th percentile over views), ``median`` over views; ``views`` counted (those seeing at least
    ``MIN_POINTS`` sparse points); ``space`` the field's space they are measured in."""

    close: float
    median: float
    views: int
    space: SceneSpace

    def matching_resolution(self) -> int:
        """Vertices per axis of the grid whose voxel equals the close footprint."""
        return self.resolution_for(1.0)

    def resolution_for(self, pixels_per_voxel: float) -> int:
        """Vertices per axis of the coarsest grid whose voxel spans at most ``pixels_per_voxel`` close-footprint
        pixels."""
        return int(math.ceil(2.0 * self.space.half_size / (self.close * pixels_per_voxel))) + 1

    def pixels_per_voxel(self, resolution: int) -> float:
        """How many close-footprint pixels one voxel of a ``resolution``³ grid spans (1: it matches; more:
        the field is blurrier than the photos)."""
        return self.space.voxel_size(resolution) / self.close

    def describe(self, resolution: int) -> dict:
        """Report figures for a field of ``resolution``³ (plain JSON values)."""
        return {"footprint_close": round(self.close, 6), "footprint_median": round(self.median, 6),
                "views": self.views, "matching_resolution": self.matching_resolution(),
                "pixels_per_voxel": round(self.pixels_per_voxel(resolution), 2)}


def capture_detail(capture: Capture, space: SceneSpace, views: Sequence | None = None) -> CaptureDetail | None:
    """The pixel footprint of ``views`` (default: the capture's training views) in ``space``; ``None`` when
    no view sees ``MIN_POINTS`` of the capture's sparse points (nothing to measure the depth with)."""
    views = capture.train_views if views is None else list(views)
    points = np.asarray(capture.points, dtype=np.float64).reshape(-1, 3)
    footprints = []
    for view in views:
        if not len(points):
            break
        uv, z = project(points, view.camera, view.c2w)
        seen = (z > 0) & inside_image(uv[:, 0], uv[:, 1], view.camera.width, view.camera.height)
        if seen.sum() >= MIN_POINTS:
            footprints.append(float(np.median(z[seen])) / view.camera.fx / space.radius)
    if not footprints:
        return None
    return CaptureDetail(float(np.percentile(footprints, CLOSE_PERCENTILE)), float(np.median(footprints)),
                         len(footprints), space)


def detailed_config(config: FieldConfig, detail: CaptureDetail | None) -> FieldConfig:
    """``config`` with one finer grid, trained from :data:`DETAIL_STAGE_AT` of the run, where its ladder is one
    of :data:`LIBRARY_LADDERS` and a voxel of that ladder's finest grid spans more than ``config.max_pixels_per_voxel``
    close-footprint pixels (see :class:`~pytest_n2r.field.config.FieldConfig`); ``config`` itself otherwise: any
    other ladder is trained as given, 0 turns this off, and nothing is added where nothing could be measured
    (``detail`` ``None``).

    The finer grid is the coarsest with at most ``max_pixels_per_voxel`` pixels a voxel, rounded up to a
    multiple of :data:`DETAIL_GRID_MULTIPLE`, at most ``detail_grid_max``.
    """
    if (config.resolutions, config.stage_fractions) not in LIBRARY_LADDERS:
        return config
    finest, limit = config.resolutions[-1], config.max_pixels_per_voxel
    if detail is None or limit <= 0 or detail.pixels_per_voxel(finest) <= limit:
        return config
    wanted = DETAIL_GRID_MULTIPLE * math.ceil(detail.resolution_for(limit) / DETAIL_GRID_MULTIPLE)
    finer = min(wanted, config.detail_grid_max)
    if finer <= finest:
        return config
    return config.replace(resolutions=(*config.resolutions, finer),
                          stage_fractions=(*config.stage_fractions, DETAIL_STAGE_AT))
